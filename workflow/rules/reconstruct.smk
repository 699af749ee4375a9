rule reconstruct:
    input:
        reconstruct_inputs,
    output:
        RESULTS / "{scene}" / "gaussians.h5",
    params:
        stage_keys_hash=keys_hash("reconstruct"),
        scene=scene_yaml,
        device=DEVICE,
    log:
        RESULTS / "{scene}" / "logs" / "reconstruct.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "reconstruct.tsv"
    container:
        image("reconstruct")
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=GPU,
    shell:
        "pm-reconstruct --scene {params.scene:q} --out {output:q} --device {params.device} > {log:q} 2>&1"

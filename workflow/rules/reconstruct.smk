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
    # One thread: most of its time is serial Python and torch between splat's kernels, so two scenes side by side
    # on two cores finish sooner than one after the other on both (snakemake sets OMP_NUM_THREADS, which splat reads).
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=GPU,
    shell:
        "pm-reconstruct --scene {params.scene:q} --out {output:q} --device {params.device} > {log:q} 2>&1"

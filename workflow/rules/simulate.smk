rule simulate:
    input:
        gaussians=RESULTS / "{scene}" / "gaussians.h5",
    output:
        trajectories=RESULTS / "{scene}" / "trajectories.h5",
        setup=report(RESULTS / "{scene}" / "setup.png", category="{scene}", subcategory="simulation",
                     caption="../report/setup.rst"),
    params:
        stage_keys_hash=keys_hash("simulate"),
        scene=scene_yaml,
        device=DEVICE,
    log:
        RESULTS / "{scene}" / "logs" / "simulate.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "simulate.tsv"
    container:
        image("simulate")
    threads: 2
    resources:
        mem_mb=4000,
        runtime=120,
        gpu=GPU,
    shell:
        "pm-simulate --scene {params.scene:q} --gaussians {input.gaussians:q} --out {output.trajectories:q}"
        " --device {params.device} > {log:q} 2>&1"

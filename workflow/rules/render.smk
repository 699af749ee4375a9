rule render:
    input:
        gaussians=RESULTS / "{scene}" / "gaussians.h5",
        trajectories=RESULTS / "{scene}" / "trajectories.h5",
    output:
        coarse=RESULTS / "{scene}" / "coarse.h5",
        video=RESULTS / "{scene}" / "coarse.mp4",
    params:
        stage_keys_hash=keys_hash("render"),
        scene=scene_yaml,
        device=DEVICE,
    log:
        RESULTS / "{scene}" / "logs" / "render.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "render.tsv"
    container:
        image("render")
    # One thread, as reconstruct: two scenes render side by side.
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
        gpu=GPU,
    shell:
        "pm-render --scene {params.scene:q} --gaussians {input.gaussians:q} --trajectories {input.trajectories:q}"
        " --out {output.coarse:q} --video {output.video:q} --device {params.device} > {log:q} 2>&1"

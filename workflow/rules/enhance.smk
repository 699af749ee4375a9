rule lora:
    input:
        gaussians=RESULTS / "{scene}" / "gaussians.h5",
        extra_views=lambda w: [str(v.image) for v in scene(w.scene).reconstruct.extra_views],
    output:
        directory(RESULTS / "{scene}" / "lora"),
    params:
        stage_keys_hash=keys_hash("lora"),
        scene=scene_yaml,
        device=DEVICE,
    log:
        RESULTS / "{scene}" / "logs" / "lora.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "lora.tsv"
    container:
        image("enhance")
    threads: 2
    resources:
        mem_mb=16000,
        runtime=240,
        gpu=GPU,
    shell:
        "pm-lora --scene {params.scene:q} --gaussians {input.gaussians:q} --out {output:q} --device {params.device} > {log:q} 2>&1"


rule invert:
    input:
        unpack(artifacts_and_lora("coarse", "gaussians")),
    output:
        RESULTS / "{scene}" / "latents.h5",
    params:
        stage_keys_hash=keys_hash("invert"),
        scene=scene_yaml,
        device=DEVICE,
        lora=optional_flag("--lora", "lora"),
    log:
        RESULTS / "{scene}" / "logs" / "invert.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "invert.tsv"
    container:
        image("enhance")
    threads: 2
    resources:
        mem_mb=16000,
        runtime=240,
        gpu=GPU,
    shell:
        "pm-invert --scene {params.scene:q} --coarse {input.coarse:q} --gaussians {input.gaussians:q}{params.lora}"
        " --out {output:q} --device {params.device} > {log:q} 2>&1"


rule enhance:
    input:
        unpack(artifacts_and_lora("coarse", "gaussians", latents=True)),
    output:
        video=report(RESULTS / "{scene}" / "video.mp4", category="{scene}", subcategory="video",
                     caption="../report/video.rst"),
        sheet=report(RESULTS / "{scene}" / "contact_sheet.png", category="{scene}", subcategory="video",
                     caption="../report/contact_sheet.rst"),
    params:
        stage_keys_hash=keys_hash("enhance"),
        scene=scene_yaml,
        device=DEVICE,
        latents=optional_flag("--latents", "latents"),
        lora=optional_flag("--lora", "lora"),
    log:
        RESULTS / "{scene}" / "logs" / "enhance.log",
    benchmark:
        RESULTS / "{scene}" / "benchmarks" / "enhance.tsv"
    container:
        image("enhance")
    # The flow backend is OpenCV on the CPU, one thread as render; only diffusion wants two, a GPU and longer.
    threads: lambda w: 2 if uses_diffusion(w.scene) else 1
    resources:
        mem_mb=8000,
        runtime=lambda w: 240 if uses_diffusion(w.scene) else 30,
        gpu=lambda w: GPU if uses_diffusion(w.scene) else 0,
    shell:
        "pm-enhance --scene {params.scene:q} --coarse {input.coarse:q} --gaussians {input.gaussians:q}"
        "{params.latents}{params.lora} --out {output.video:q} --device {params.device} > {log:q} 2>&1"

def reconstruct_inputs(wildcards):
    """The files reconstruct reads besides scene.yaml: photograph, masks, hint images, initial PLY, extra views."""
    s = scene(wildcards.scene)
    files = [s.image] + [o.mask for o in s.objects if o.mask is not None] + [o.hints for o in s.objects if o.hints]
    files += [s.reconstruct.init_ply] if s.reconstruct.init_ply else []
    return [str(f) for f in files + [v.image for v in s.reconstruct.extra_views]]


rule reconstruct:
    input:
        reconstruct_inputs,
    output:
        RESULTS / "{scene}" / "gaussians.h5",
    params:
        stage_keys_hash=keys_hash("reconstruct"),
        scene=scene_yaml,
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
        "pm-reconstruct --scene {params.scene:q} --out {output:q} --device " + DEVICE + " > {log:q} 2>&1"

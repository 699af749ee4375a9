# The plots of `snakemake --report report.html`: drawn from the artifacts and the benchmark files by pm-plots.
# A local rule: it runs where snakemake runs (the project's environment, which has pm-plots), in no image
# (a `run:` directive, which no software deployment method moves into one).
localrules:
    plots,


rule plots:
    input:
        gaussians=RESULTS / "{scene}" / "gaussians.h5",
        trajectories=RESULTS / "{scene}" / "trajectories.h5",
        video=RESULTS / "{scene}" / "video.mp4",  # after the last stage, so every stage's time is known
    output:
        energy=report(RESULTS / "{scene}" / "report" / "energy.svg", category="{scene}", subcategory="simulation",
                      caption="../report/energy.rst"),
        momentum=report(RESULTS / "{scene}" / "report" / "momentum.svg", category="{scene}", subcategory="simulation",
                        caption="../report/momentum.rst"),
        loss=report(RESULTS / "{scene}" / "report" / "loss.svg", category="{scene}", subcategory="reconstruction",
                    caption="../report/loss.rst"),
        times=report(RESULTS / "{scene}" / "report" / "stage_times.svg", category="{scene}", subcategory="stage times",
                     caption="../report/stage_times.rst"),
    params:
        benchmarks=lambda w: str(RESULTS / w.scene / "benchmarks"),
        out=lambda w: str(RESULTS / w.scene / "report"),
    log:
        RESULTS / "{scene}" / "logs" / "plots.log",
    run:
        shell("pm-plots --gaussians {input.gaussians:q} --trajectories {input.trajectories:q}"
              " --benchmarks {params.benchmarks:q} --out {params.out:q} > {log:q} 2>&1")

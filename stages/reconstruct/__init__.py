"""pm-reconstruct: one photograph -> 3D Gaussians of its objects (paper section 3.3).

Pipeline (each step its own module; pipeline.py chains them, cli.py writes gaussians.h5):
  segment    objects' masks: mask files, boxes refined by GrabCut or SAM, image alpha
  background the photograph with the objects inpainted away (PatchMatch exemplar fill)
  depth      a metric depth prior: silhouette inflation, or a DPT/MiDaS model
  lift       initial Gaussians: the front surface lifted, the back closed, the rim walled
  ply        or initial Gaussians from another tool's 3DGS PLY, placed into the input camera
  views      the supervised views: the input view and extra views (Eq. 9)
  losses     colour (Eq. 10) and hard-depth (Eq. 7-8) losses
  optimize   the optimisation through splat with the paper's schedule
Helpers: geometry (cameras), local_model (local model loading), metrics. The ray-cast
shapes that tests and benchmarks take for ground truth are in testing/photographs.py.
"""

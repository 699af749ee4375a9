"""pm-reconstruct: one photograph -> 3D Gaussians of its objects (paper section 3.3).

Pipeline (each step its own module):
  segment    objects' masks: image alpha, mask files, GrabCut boxes, or SAM
  background the photograph with the objects inpainted away (OpenCV)
  depth      a metric depth prior: silhouette inflation, or a DPT/MiDaS model
  lift       initial Gaussians: the front surface lifted, the back closed (or a PLY)
  optimize   colour + hard-depth optimisation through splat (Eq. 7-10)
  cli        the program, writing gaussians.h5 through schemas
"""

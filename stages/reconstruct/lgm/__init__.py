"""The learned prior of the unseen half (``reconstruct.prior: lgm``, paper Sec. 3.3).

An image-conditioned multi-view diffusion model (ImageDream) makes four views of
the segmented object at elevation 0 and azimuths 0, 90, 180, 270 degrees; LGM's
asymmetric U-Net (Tang et al., ECCV 2024) turns those views and their Pluecker
ray embeddings into per-pixel Gaussians (splatter images); the Gaussians are
placed into the input camera and the usual optimisation starts from them.

Modules: ``rays`` (LGM's cameras and Pluecker embedding), ``unet`` (LGM),
``splatter`` (the 14 channels to Gaussians), ``multiview`` (ImageDream's UNet
and sampler), ``loading`` (local weights only), ``placement`` (into the input
camera, the volume), ``prior`` (the whole path for one object).
"""

"""Helpers for tests and benchmarks only, shipped in no install or stage image.

photographs    ray-cast shapes of known volume, inertia and colour, photographed by a pinhole camera
particles      Gaussians on the surfaces of boxes and spheres, for the simulator and the renderer
tiny_scene     a 64x48 px disc and a scene.yaml that runs the whole workflow in seconds
tiny_diffusion a Stable-Diffusion-2.1-shaped model with random weights (no downloads)
tiny_lgm       LGM and ImageDream of the published architectures, scaled down, with random weights
workflow       the example workflow's snakemake command line, run as the README runs it
"""

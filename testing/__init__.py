"""Helpers for tests and benchmarks only, shipped in no install or stage image.

photographs    ray-cast shapes of known volume, inertia and colour, photographed by a pinhole camera
particles      Gaussians on the surfaces of boxes and spheres, for the simulator
tiny_diffusion a Stable-Diffusion-2.1-shaped model with random weights (no downloads)
"""

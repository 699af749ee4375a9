"""The diffusion backend of pm-enhance (paper Sec. 3.4): Stable Diffusion 2.1 with depth and
Canny ControlNets, DDIM+ inversion (pm-invert), optional LoRA personalisation (pm-lora), and
coarse/enhanced sampling with feature injection and keyframe attention.

Modules: models (finding and loading weights), components (the loaded models' calls),
conditioning (control images), inversion, attention + injection (processors and hooks),
keyframes (Eq. 14-15), sampling, lora, pipeline (artifacts to frames). Tiny random-weight
models for tests are in testing/tiny_diffusion.py.
"""
from .pipeline import enhance_video, make_latents

__all__ = ["enhance_video", "make_latents"]

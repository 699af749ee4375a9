"""pm-enhance: coarse frames -> the final video (flow and diffusion backends)."""

"""pm-render: the simulated particles through splat from the input camera, with the source maps the
flow enhancement reads (render.py, source_map.py)."""

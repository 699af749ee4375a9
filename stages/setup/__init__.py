"""pm-setup: set a scene up in the browser, see its masks and a quick preview before the long run.

  cli         pm-setup DIR [--image PHOTO]: the command, serving one page on 127.0.0.1
  server      the Starlette app: the page's assets, the scene folder's files, the JSON API
  scene_file  scene.yaml and hint images read and written atomically, checked by schemas.load_scene
  preview     the quick coarse pass through the stage programs, cancellable
  plots       pm-plots: the Snakemake report's energy, momentum, loss and stage-time plots (SVG)
  static/     the page (HTML, CSS, plain JavaScript on a canvas): nothing is loaded from the network

Only plots runs inside the workflow; it needs no more than the core dependencies. The rest needs
the `setup` extra (starlette, uvicorn).
"""

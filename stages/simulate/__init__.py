"""pm-simulate: MLS-MPM simulation of the reconstructed objects.

PHYSMOTION_WARP_DEBUG=1 compiles every Warp kernel loaded in this process in
Warp's debug mode, where array indexing is bounds-checked: an index off the
grid stops the program with an assertion naming the array access instead of
silently corrupting memory (release CPU kernels do not check bounds). It is
set here, before any kernel module is loaded, so it is the one switch for all
of stages.simulate; benchmarks/debug_kernels.py runs a small simulation with it.
"""
import os

import warp as wp

if os.environ.get("PHYSMOTION_WARP_DEBUG", "") == "1":
    wp.config.mode = "debug"
    # Warp's CPU kernels keep their tile scratch space behind one process-wide
    # pointer to the launching thread's stack; unoptimised debug code really
    # dereferences it, so the solver's concurrent launches from two threads
    # would crash. Static scratch space is safe to share (these kernels use no tiles).
    wp.config.enable_tiles_in_stack_memory = False

"""pm-simulate: MLS-MPM simulation of the reconstructed objects (and pm-render)."""

"""The facts every stage shares: the world frame and geometry, the object catalogue and meshes, the pulse, seeds, atomic writes, capture-set names."""

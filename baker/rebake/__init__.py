"""Incremental rebakes: the bake state, what changed since it, and the texels recomputed."""

"""The scene in world space: every triangle (``world``) and what a surface looks like at a point (``surface``)."""

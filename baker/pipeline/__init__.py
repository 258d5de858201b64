"""The full bake: the plan, the parts of texels, the stages run in order (``full``)."""

"""The baked glTF written back: the input asset plus lightmap UVs, images and materials."""

"""Light at every texel: the obscurance terms, translucency, direct light, ambient terms, path-traced GI."""

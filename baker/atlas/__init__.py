"""The lightmap atlas and its texels: unwrap, rasterise, validity of sample points, supersampling."""

"""Lightmap pages: composed from the terms, post-processed, denoised, encoded, written as float files."""

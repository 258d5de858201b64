"""Rays: deterministic sample points (``sampling``) and the only module that talks to Embree (``trace``)."""

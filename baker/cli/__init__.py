"""The ``baker`` command line: a thin layer over the library's public API (``baker.bake``)."""

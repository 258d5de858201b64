"""What ``vulture`` cannot see used in ``baker`` (``tests/test_dead_code.py`` reads this file
with the package; it is never imported): hooks that Python, numpy, numba, xatlas and the
standard library call or read by name, values a user reads of the API's results, a prototype's
constant, and three functions left for a change that holds their files. Anything else vulture
finds is dead code."""

# Python, numpy, numba, xatlas and http.server read or call these by name.
__getattr__  # baker/__init__.py: the package's lazy public names (PEP 562)
_.texels_per_unit  # atlas/charts.py: xatlas.PackOptions, read by xatlas
_.bilinear  # atlas/charts.py: xatlas.PackOptions
_.resolution  # atlas/charts.py: xatlas.PackOptions
_.create_image  # atlas/charts.py: xatlas.PackOptions
_.writeable  # numpy's array flags (read-only hand-offs: frozen.py, world.py, unwrap.py)
signum  # cli/__init__.py, cli/main.py: a signal handler's arguments, as signal.signal calls it
_.get_source_stamp  # jit.py: numba's cache locator
_.__qualname__  # jit.py: a kernel's name, as numba's cache reads it
_.on_start  # run/compile_clock.py: numba's event listener
_.on_end  # run/compile_clock.py: numba's event listener
ev  # run/compile_clock.py: the listener's argument
_.log_message  # view.py: http.server's request log, silenced

# Read by a user of the API, or stored in the bake state.
lightmap_texcoord  # output/write.py: WriteInfo, what baker.write returns
calibration  # study.py: do the error estimates hold? (docs/model.md, bench_calibration.py)
back_fraction  # atlas/validity.py: Validity's field, written to the bake state

# Used only by tests, as the plain statement of what a compiled pass computes (the directions a
# texel's kernel draws, a texel's standard error, the texels' masks on the pages), which the
# tests hold the kernels to; the next change of these files moves them into the tests.
_.standard_error  # light/hemisphere.py: Terms.standard_error
_.page_masks  # atlas/validity.py: Validity.page_masks
cosine_directions  # light/hemisphere.py: the bake draws its directions in its kernels now

# The world-space filter, a prototype not yet in the bake (docs/design.md): its widths, read by
# its docstring and bench_world_filter.py.
WIDTHS  # image/world_filter.py

# glTF properties baker reads into its objects and writes back as the file had them, but never
# reads itself (gltf/objects.py: a field dropped would drop the property from the output).
generator, copyright, minVersion  # Asset
zfar, znear  # Perspective, Orthographic
magFilter, minFilter  # Sampler
inverseBindMatrices, skeleton, joints  # Skin
mimeType  # Image
interpolation  # AnimationSampler
extensionsUsed, extensionsRequired, skins  # GLTF2

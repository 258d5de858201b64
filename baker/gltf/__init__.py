"""Reading glTF: the JSON document, the ``Scene`` handed to the pipeline, what a material does to a ray."""

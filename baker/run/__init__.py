"""Running work: threads, forked children, progress bars, rows spilled to disk, atomic files."""

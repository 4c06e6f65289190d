"""EDS model, writer, reader and checker."""

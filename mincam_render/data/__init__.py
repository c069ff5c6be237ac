"""Layer 4: datasets on disk.

Format, shards and manifests, the render job (the one entry point that renders
a dataset), plan cache, local and Ray executors.
"""

"""Layer 6: learning: minimalist and baseline camera models, the task head, training."""

"""Layer 5: masks for printing (PNG, SVG, PDF, EXR) from trained logits."""

"""Task Specification Trees (seed 000 Sec. III)."""

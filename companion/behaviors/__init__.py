"""The executive layer (seed 001 Sec. 5-7): behaviors, the behavior coordinator, beliefs, processes."""

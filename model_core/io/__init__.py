"""Files in and out: BVH reading and writing, released checkpoints, atomic writes."""

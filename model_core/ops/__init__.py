"""The editing operations on a user's clip: normalise, extend, denoise, fuse, foot lock, follow a path."""

"""The stages of each operation (extend, denoise, foot lock, follow): scene in, model, solve, new action out."""

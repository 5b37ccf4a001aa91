"""The scene adapter: armatures, actions and curves in, joint positions out, and keys back in."""

"""Motion itself: the conventions (axes, joints, feature layout), features, rotations and synthetic clips."""

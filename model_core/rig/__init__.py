"""Rigs: loading clips onto the canonical skeleton, bone maps, and solving a rig's bones to joint positions."""

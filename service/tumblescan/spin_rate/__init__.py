"""Spin rate (and axis) of a single-axis spinner from a monocular image sequence (kind ``spin-from-images``)."""

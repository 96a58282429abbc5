"""Job kind ``panel-axis``: the direction of a satellite's solar-panel axis from one optical image
(seed 002, Song et al. 2020), with its uncertainty and a weak-perspective ambiguity verdict."""

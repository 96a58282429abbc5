"""The member-prism bench (``bench/linescan/member_prism.py``): a square section's roll and
half-width from points on its outline, and a boom's prism from noise-free frames."""

from __future__ import annotations

import numpy as np
from bench.linescan.member_prism import prism_rows, roll_and_half_width
from bench.linescan.real_shapes import shape_named
from bench.linescan.reuse_diag import at_truth

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense.beams import find_beams

from ..conftest import motion_for


def test_the_roll_and_half_width_of_a_square_from_its_outline() -> None:
    rng = np.random.default_rng(4)
    # Points on two faces of a 10 cm square turned by 30 deg, with 2 mm of noise.
    t = rng.uniform(-0.05, 0.05, 400)
    face = rng.integers(0, 2, 400)
    a = np.where(face == 0, 0.05, t) + rng.normal(0, 0.002, 400)
    b = np.where(face == 0, t, -0.05) + rng.normal(0, 0.002, 400)
    psi = np.radians(30.0)
    found_psi, h = roll_and_half_width(np.cos(psi) * a - np.sin(psi) * b, np.sin(psi) * a + np.cos(psi) * b)
    assert abs(np.degrees(found_psi) - 30.0) < 1.0 and abs(h - 0.05) < 0.002


def test_a_booms_prism_from_noise_free_frames_is_its_section() -> None:
    scene = Scene(scanner=Scanner(lines=200, pixels=200), shape=shape_named("dish-boom"), noise=False)
    _, data, mapping, surf = at_truth(motion_for(1, distance_m=50.0), scene, 1)
    beams = find_beams(data, mapping, surf, scene.scanner.noise)
    lin, fits = prism_rows(beams, data, mapping, scene.scanner.noise)
    # The boom (10 cm square): its half-width, and every kept hit on its face.
    assert len(fits) == beams.members == 1
    assert abs(fits[0].half_width_m - 0.05) < 1e-4 and fits[0].kept > 0.3 * fits[0].hits
    assert len(lin.r) == fits[0].kept and np.sqrt(np.mean(lin.r**2 / lin.var)) < 0.01
    assert lin.J.shape == (len(lin.r), len(mapping.free))

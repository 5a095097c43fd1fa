"""Shared fixtures of the libmr Python tests (run by ctest: python_* with PYTHONPATH=build/python)."""

import os
import pathlib

import numpy as np
import pytest

SOURCE_DIR = pathlib.Path(os.environ.get("MR_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
SAMPLES = SOURCE_DIR / "sample_photos"


@pytest.fixture
def rng():
    return np.random.default_rng(15)


def sky_only_scene(libmr, sigma_t=0.02, sky=(0.8, 0.85, 0.9)):
    """A homogeneous fog lit by the sky alone: the closed form C = I T + L (1 - T) holds."""
    scene = libmr.Scene()
    scene.medium.sigma_t_per_m = (sigma_t, sigma_t * 1.5, sigma_t * 2.0)
    scene.lighting.sky_radiance = sky
    return scene

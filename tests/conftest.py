import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# numba compiles (or loads its cache) on a kernel's first call, which can take longer than
# Hypothesis' per-example deadline: timing is not what these tests check
settings.register_profile("omaps", deadline=None)
settings.load_profile("omaps")

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("OMAPS_SHARED", ROOT.parent / "shared"))
TEXTURES = SHARED / "data" / "textures"
SCENES = SHARED / "data" / "scenes"


def real_textures(min_size=0):
    """Paths of the real alpha textures in ../shared (empty when absent)."""
    if not TEXTURES.is_dir():
        return []
    from PIL import Image

    out = []
    for p in sorted(TEXTURES.glob("*.png")):
        with Image.open(p) as im:
            if min(im.size) >= min_size:
                out.append(p)
    return out


needs_shared = pytest.mark.skipif(not TEXTURES.is_dir(),
                                  reason=f"real textures not found at {TEXTURES} (../shared is absent)")


needs_scenes = pytest.mark.skipif(not (SCENES / "palm.glb").is_file(),
                                  reason=f"scenes not found at {SCENES} (../shared is absent)")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)

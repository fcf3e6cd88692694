"""reference_scenes/many_lights: the committed XML is its generator's
output, it holds the 10 000 emitters its card describes, and the copy
Mitsuba's reference renders differs from it only by each emitter's
sampling_weight (its power). Deterministic checks; the statistical ones
are the estimator matrix's cells (tests/test_estimator_matrix.py)."""
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest

import radiometer as rm
from radiometer.reference_scenes import registry
from radiometer.reference_scenes.many_lights import generate as G

WEIGHT = re.compile(r'<float name="sampling_weight" value="([^"]+)"/>')


def test_committed_files_are_the_generators_output():
    assert G.XML.read_text() == G.scene_xml(), "scene.xml differs: rerun python -m ...many_lights.generate"
    assert G.OBJ.read_text() == G.tube_obj()
    # committed small: ~1.3 MB of text (git stores it zlib-compressed, ~0.1 MB)
    assert G.XML.stat().st_size < 1.5e6


def test_ten_thousand_emitters_of_very_different_power():
    scene = rm.load_file(G.XML, res=8)
    points = [e for e in scene.desc.emitters if e.type == "point"]
    area = [s for s in scene.desc.shapes if getattr(s, "emitter", None) is not None]
    assert len(points) == G.N_POINTS and len(area) == G.N_DOWN + G.N_UP + G.N_TUBES
    assert len(points) + len(area) == G.N_EMITTERS >= 10_000
    em = G.emitters()
    phi = np.array([e[3] for e in em])
    assert phi.max() / phi.min() > 1e5  # five decades
    back = np.mean([e[1][2] < G.ZP for e in em if e[0] != "tube"])
    assert abs(back - G.BACK_FRACTION) < 0.01
    # the points keep their clearance from the floor, the ceiling and the walls
    p = np.array([e[1] for e in em if e[0] == "point"])
    assert p[:, 1].min() >= G.CLEARANCE - 0.005 and p[:, 1].max() <= G.H - G.CLEARANCE + 0.005
    assert np.abs(p[:, 0]).max() <= G.X - G.CLEARANCE + 0.005


def test_mitsuba_copy_differs_only_by_sampling_weight():
    """Mitsuba renders the scene with sampling_weight = power (registry's
    mitsuba_writer); stripped of the weights it is scene.xml, and every
    weight is its emitter's power. Our loader refuses the parameter (it is
    not ours: our selection is the estimator's light_sampler), which is why
    the weights live in Mitsuba's copy only."""
    with tempfile.TemporaryDirectory() as d:
        path = G.write_weighted(Path(d) / "scene.xml")
        text = path.read_text()
        assert (Path(d) / "tube.obj").read_text() == G.tube_obj()
        with pytest.raises(rm.SceneError, match="sampling_weight"):
            rm.load_file(path)
    assert WEIGHT.sub("", text) == G.scene_xml()
    w = np.array([float(x) for x in WEIGHT.findall(text)])
    phi = np.array([e[3] for e in G.emitters()])
    assert len(w) == G.N_EMITTERS
    np.testing.assert_allclose(w, phi, rtol=1e-5)
    assert registry.get("many_lights").mitsuba_writer == "generate:write_weighted"


def test_reference_says_what_mitsuba_rendered():
    ref = rm.read_exr(registry.get("many_lights").reference_exr)
    assert "write_weighted" in ref.metadata.get("scene_note", ""), ref.metadata

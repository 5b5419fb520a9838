"""Any manifest text gives a Manifest or a located ManifestError, never another exception."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.manifest.loader import ManifestError, load_manifest

from .helpers import SAMPLES, library

DEMO = (SAMPLES / "uwgen.yaml").read_text()
PIECES = [":", "-", " ", "\n", "{", "}", "[", "]", "'", '"', "#", "0", "256", "-1", "null", "true", "fifo",
          "id", "name", "depth", "&a", "*a", "!!str", "\t", "rmw_desert", "/x", "std_srvs/SetBool", "é"]


@st.composite
def mutated_demo(draw):
    text = DEMO
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        if draw(st.booleans()):
            text = text[:at] + draw(st.sampled_from(PIECES)) + text[at:]
        else:
            text = text[:at] + text[at + draw(st.integers(1, 12)):]
    return text


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mutated_demo())
def test_mutated_manifests_load_or_fail_with_a_located_error(tmp_path, text):
    path = tmp_path / "uwgen.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        manifest = load_manifest(path, library())
    except ManifestError as error:
        assert error.where is not None and error.where.path == path
        assert 1 <= error.where.line <= text.count("\n") + 2
        assert error.where.column >= 1
    else:
        assert manifest.network and manifest.sides

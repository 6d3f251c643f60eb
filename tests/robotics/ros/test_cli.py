"""``semattnet ros2``'s options: predict's own model options, the domain and the names refused in one line."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.cli.predict import predict
from semattnet.cli.ros import MODEL_OPTIONS, ros2


def test_model_options_are_predicts_own() -> None:
    names = {p.name for p in MODEL_OPTIONS}
    assert {"weights", "method", "device", "amp", "backend", "precision", "calibration"} <= names
    assert all(any(p is q for q in predict.params) for p in MODEL_OPTIONS)  # the same objects, not copies
    assert {p.name for p in ros2.params} >= names | {"segment_spec", "palette_mismatch", "domain_id", "namespace"}


@pytest.mark.parametrize(
    "args,env,why",
    [
        (["--method", "classical"], {"ROS_DOMAIN_ID": "lots"}, "ROS_DOMAIN_ID='lots': expected a domain id 0-232"),
        (["--method", "classical", "--domain-id", "300"], {}, "300 is not in the range 0<=x<=232"),
        (["--method", "classical", "--namespace", "/bad name"], {}, "--namespace '/bad name': expected names"),
        (["--method", "classical", "--image-topic", "cam//x y"], {}, "--image-topic 'cam//x y': expected names"),
        ([], {}, "--checkpoint or --weights is required (or --method classical)"),
    ],
)
def test_bad_options_are_one_line(args: list[str], env: dict[str, str], why: str) -> None:
    res = CliRunner().invoke(main, ["ros2", *args], env=env)
    assert res.exit_code in (1, 2) and why in res.output, res.output
    assert "Traceback" not in res.output

"""``semattnet ros2`` / ``ros1``'s options: the one Model section, the domain and the names refused in one line."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.cli.ros import ros1, ros2


def test_each_node_takes_the_model_section_and_its_own_transports_options() -> None:
    model = {"weights", "method", "device", "amp", "backend", "precision", "calibration"}
    shared = model | {"segment_spec", "palette_mismatch", "namespace", "image_topic", "live", "rerun_serve"}
    assert {p.name for p in ros2.params} >= shared | {"domain_id", "loopback"}
    assert {p.name for p in ros1.params} >= shared | {"master", "host"}
    assert not {p.name for p in ros1.params} & {"domain_id", "loopback"}


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

"""The parameter definitions, config/detector.yaml and the params-file reader agree."""

from pathlib import Path

import pytest

from clusterfilter_ros.config import all_param_specs, detector_yaml, load_params_file
from clusterfilter_ros.core.params import ParamSet, ParamSpec, parse_assignments
from clusterfilter_ros.errors import InputError, ParameterError

ROOT = Path(__file__).resolve().parents[1]


def test_detector_yaml_in_sync_with_definitions():
    assert (ROOT / "config" / "detector.yaml").read_text() == detector_yaml(), (
        "config/detector.yaml is stale: run `clusterfilter params > config/detector.yaml`"
    )


def test_yaml_round_trips_every_default():
    values = load_params_file(ROOT / "config" / "detector.yaml")
    specs = all_param_specs()
    assert set(values) == {s.name for s in specs}
    for spec in specs:
        assert spec.validate(values[spec.name]) == spec.default, spec.name
        if spec.kind == "float":
            assert isinstance(values[spec.name], float), f"{spec.name} must be written as x.0"


def test_param_names_unique_and_defaults_valid():
    specs = all_param_specs()
    names = [s.name for s in specs]
    assert len(names) == len(set(names))
    for s in specs:
        assert s.validate(s.default) == s.default
        assert s.description


def test_validation_rejects_with_reason():
    spec = ParamSpec("eps", "float", 2.0, "radius", minimum=0.05, maximum=20.0)
    with pytest.raises(ParameterError, match="below its minimum"):
        spec.validate(0.0)
    with pytest.raises(ParameterError, match="expects float"):
        spec.validate("abc")
    with pytest.raises(ParameterError, match="finite"):
        spec.validate(float("nan"))
    assert spec.validate(1) == 1.0


def test_paramset_update_is_atomic():
    specs = [
        ParamSpec("a", "int", 1, "a", minimum=0),
        ParamSpec("b", "float_list", [0.0, 0.0], "b", length=2),
    ]
    ps = ParamSet(specs)
    with pytest.raises(ParameterError):
        ps.update({"a": 5, "b": [1.0]})
    assert ps.a == 1
    ps.update(parse_assignments(["a=3", "b=1.5,2"]))
    assert ps.a == 3 and ps.b == [1.5, 2.0]
    with pytest.raises(ParameterError, match="unknown parameter"):
        ps.update({"zzz": 1})


def test_paramset_copies_and_pickles():
    import copy
    import pickle

    from clusterfilter_ros.core.params import detector_params

    ps = detector_params({"eps": 1.5})
    for clone in (copy.deepcopy(ps), copy.copy(ps), pickle.loads(pickle.dumps(ps))):
        assert clone == ps and clone.eps == 1.5
        clone.eps = 2.0  # validated, and independent of the original
        assert ps.eps == 1.5
    with pytest.raises(AttributeError):
        ps.__no_such_special__  # noqa: B018


def test_params_file_errors_are_one_line(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_params_file(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(InputError, match="not readable YAML"):
        load_params_file(bad)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("epss: 1.0\n", r"unknown parameter epss \(did you mean eps\?\)"),
        ("/**:\n  ros__parameters:\n    min_cluster_point: 5\n", "min_cluster_points"),
        ("/**:\n  ros_parameters:\n    eps: 1.0\n", "needs a ros__parameters: mapping"),
        ("/**:\n  ros__parameters: [eps, 1.0]\n", "ros__parameters must hold a mapping"),
        ("eps: 1.0\nfoo: 1\nbar: 2\n", "unknown parameters foo, bar"),
    ],
)
def test_a_misspelt_or_misplaced_parameter_is_refused_not_ignored(tmp_path, text, message):
    path = tmp_path / "params.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        load_params_file(path)


def test_node_and_standard_ros_parameters_are_accepted(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text(
        "detector:\n  ros__parameters:\n    eps: 1.5\n    avia_topic: /livox/avia\n"
        "    use_sim_time: true\n"
    )
    assert load_params_file(path) == {"eps": 1.5, "avia_topic": "/livox/avia", "use_sim_time": True}


def test_another_nodes_block_in_a_shared_params_file_is_left_alone(tmp_path):
    # A launch setup's file with several nodes: only this node's block is checked.
    path = tmp_path / "params.yaml"
    path.write_text(
        "detector:\n  ros__parameters:\n    eps: 1.5\n"
        "livox_driver:\n  ros__parameters:\n    xfer_format: 0\n    frame_id: livox\n"
    )
    values = load_params_file(path)
    assert values["eps"] == 1.5
    path.write_text(
        "/rig/clusterfilter_detector:\n  ros__parameters:\n    eps: 1.5\n"
        "    min_cluster_point: 5\n"
        "livox_driver:\n  ros__parameters:\n    xfer_format: 0\n"
    )
    with pytest.raises(InputError, match="min_cluster_point .did you mean min_cluster_points"):
        load_params_file(path)

import subprocess
import sys

import pytest

from gatmo.cli import main
from gatmo.config import GatmoModel, load_model
from gatmo.errors import ConfigError, FormatError, GatmoError


class Demo(GatmoModel):
    max_range_m: float = 10.0
    beams: int = 181


def test_load_model_reports_key_and_line(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("max_range_m: 4.0\nbeams: lots\n")
    with pytest.raises(ConfigError) as e:
        load_model(Demo, p)
    assert e.value.line == 2 and e.value.field == "beams" and str(p) in str(e.value)
    p.write_text("max_range_m: 4.0\nbogus_key: 1\n")
    with pytest.raises(ConfigError, match="unknown key") as e:
        load_model(Demo, p)
    assert e.value.line == 2 and e.value.field == "bogus_key"
    p.write_text("max_range_m: 4.0\n")
    assert load_model(Demo, p).max_range_m == 4.0


def test_yaml_syntax_error_has_line(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("a: 1\nb: [1, 2\n")
    with pytest.raises(FormatError) as e:
        load_model(Demo, p)
    assert e.value.line is not None


def test_error_formatting():
    e = GatmoError("expected 180 readings", file="run.clf", line=12, field="FLASER")
    assert str(e) == "run.clf:12: FLASER: expected 180 readings"


def test_cli_version(capsys):
    assert main(["--version"]) == 0
    assert "gatmo" in capsys.readouterr().out


def test_cli_error_is_one_red_line_exit_1(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [\n")
    r = subprocess.run(
        [sys.executable, "-m", "gatmo", "config", "dump", "nonsense"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 1
    assert "Traceback" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "component" in lines[0]
    r = subprocess.run(
        [sys.executable, "-m", "gatmo", "--debug", "config", "dump", "nonsense"],
        capture_output=True,
        text=True,
    )
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_cli_usage_error_exit_2():
    assert main(["localize"]) == 2


def test_a_config_an_earlier_version_wrote_loads_but_a_removed_option_set_is_refused(tmp_path):
    # a run writes its whole config, every field; options removed later appear there at the
    # value they had by default, and such a file must still load
    import yaml

    from gatmo.objects.config import GatmoConfig
    from gatmo.pipeline.config import StackConfig, dump_stack_config, load_stack_config
    from gatmo.pipeline.stack import FusionConfig

    for model in (GatmoConfig, FusionConfig):
        assert model.removed_options
        assert not set(model.removed_options) & set(model.model_fields)
    doc = yaml.safe_load(dump_stack_config(StackConfig()))
    doc["gatmo"].update(GatmoConfig.removed_options)
    doc["fusion"].update(FusionConfig.removed_options)
    doc["fusion"]["gatmo_pose_gain"] = 1  # an int where the dump wrote 1.0: the same value
    p = tmp_path / "config.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert dump_stack_config(load_stack_config(p)) == dump_stack_config(StackConfig())
    good = p.read_text()
    # set to anything else, the option asks for behaviour that is gone
    for section, key, value in (("fusion", "bridge_evidence", True),
                                ("gatmo", "chair_align_cells", 2),
                                ("fusion", "verified_track", 1)):  # 1 is not True here
        bad = yaml.safe_load(good)
        bad[section][key] = value
        p.write_text(yaml.safe_dump(bad, sort_keys=False))
        with pytest.raises(ConfigError, match="removed option") as e:
            load_stack_config(p)
        assert e.value.field == f"{section}.{key}"
        assert p.read_text().splitlines()[e.value.line - 1].strip().startswith(f"{key}:")


def _config_models():
    """Every config model a user sets, reached from the stack's and the simulator's roots."""
    import inspect

    from pydantic import BaseModel

    from gatmo.datasets.sim import SimConfig
    from gatmo.pipeline.config import MapBuildConfig, StackConfig

    seen, todo = [], [StackConfig, SimConfig, MapBuildConfig]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.append(m)
        for f in m.model_fields.values():
            if inspect.isclass(f.annotation) and issubclass(f.annotation, BaseModel):
                todo.append(f.annotation)
    return seen


def test_every_parameter_has_a_description():
    models = _config_models()
    assert len(models) >= 11  # stack, amcl, gatmo, icp, fusion, sim and its parts, map build
    missing = [f"{m.__name__}.{k}" for m in models for k, f in m.model_fields.items()
               if not (f.description or "").strip()]
    assert not missing, f"parameters without a description: {missing}"


def test_commented_dump_loads_back_to_the_same_configuration(tmp_path):
    import yaml

    from gatmo.config import dump_model, load_model
    from gatmo.datasets.sim import SimConfig
    from gatmo.localization.config import AmclConfig
    from gatmo.pipeline.config import (
        MapBuildConfig,
        StackConfig,
        load_map_build_config,
        load_stack_config,
    )

    cfg = StackConfig()
    cfg.amcl.sigma_hit_m = 0.123  # a value off its default survives the round trip
    cfg.gatmo.absence_far_hits = True
    build = MapBuildConfig()
    build.graph.match.min_score = 0.55
    for model in (cfg, SimConfig(), AmclConfig(max_beams=33), build):
        text = dump_model(model, comments=True)
        assert yaml.safe_load(text) == yaml.safe_load(dump_model(model))
        # every field is written, and the descriptions are there as comments
        assert sum(t.lstrip().startswith("# ") for t in text.splitlines()) > 20
        assert all(len(line) <= 100 for line in text.splitlines())
    p = tmp_path / "stack.yaml"
    p.write_text(dump_model(cfg, comments=True))
    assert load_stack_config(p) == cfg
    p.write_text(dump_model(SimConfig(), comments=True))
    assert load_model(SimConfig, p) == SimConfig()
    p.write_text(dump_model(build, comments=True))
    assert load_map_build_config(p) == build != MapBuildConfig()


def test_cli_config_dump_writes_descriptions(capsys):
    import yaml

    from gatmo.config import dump_model
    from gatmo.objects.config import GatmoConfig

    assert main(["config", "dump", "gatmo"]) == 0
    out = capsys.readouterr().out
    described = GatmoConfig.model_fields["absence_max_range_m"].description.split()[0]
    line = out.splitlines().index("absence_max_range_m: 5.0")
    assert out.splitlines()[line - 1].startswith("# ") and described in out
    assert yaml.safe_load(out) == yaml.safe_load(dump_model(GatmoConfig()))
    assert main(["config", "dump", "gatmo", "--no-comments"]) == 0
    assert capsys.readouterr().out == dump_model(GatmoConfig())


def test_cli_config_dump_stack_presets_load_back_as_the_named_configurations(tmp_path, capsys):
    from gatmo.pipeline.config import (
        STACK_PRESETS,
        StackConfig,
        load_stack_config,
        real_stack_config,
        sim_stack_config,
    )

    expected = {"amcl": StackConfig(), "sim": sim_stack_config(), "real": real_stack_config()}
    assert set(expected) == set(STACK_PRESETS)
    for name, cfg in expected.items():
        assert main(["config", "dump", "stack", "--preset", name]) == 0
        p = tmp_path / f"{name}.yaml"
        p.write_text(capsys.readouterr().out)
        assert load_stack_config(p) == cfg, name
    real = expected["real"]
    # the real logs' configuration: AMCL's wheels and initial cloud, the sharp model with the
    # anchor filter on AMCL's flat one beside it
    assert (real.amcl.alpha1, real.amcl.laser_model, real.amcl.sigma_hit_m) == (
        0.2, "likelihood_field_prob", 0.1)
    assert real.amcl.initial_cov_xx_m2 == StackConfig().amcl.initial_cov_xx_m2
    assert real.fusion.anchor_filter and real.fusion.anchor_laser_model == "likelihood_field"
    flat = real_stack_config(sharp_model=False)
    assert flat.amcl.laser_model == "likelihood_field" and not flat.fusion.anchor_filter
    # a preset names a stack configuration only, and an unknown one is one line, exit 1
    assert main(["config", "dump", "stack", "--preset", "nope"]) == 1
    assert main(["config", "dump", "amcl", "--preset", "sim"]) == 1
    err = capsys.readouterr().err
    assert "unknown preset 'nope': amcl | sim | real" in err and "--preset" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("user", [None, "ACTIVE"])
def test_importing_gatmo_makes_openmp_wait_passively_unless_the_user_said_otherwise(user):
    """numba's OpenMP threads spin while idle by default, and two gatmo processes on the same
    cores slowed each other 3-7x (docs/experiments.md, forty-eighth session): importing gatmo
    sets OMP_WAIT_POLICY=PASSIVE, before any kernel starts the runtime, unless it is set."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if user:
        env["OMP_WAIT_POLICY"] = user
    code = "import os, gatmo; print(os.environ['OMP_WAIT_POLICY'])"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       check=True)
    assert r.stdout.strip() == (user or "PASSIVE")

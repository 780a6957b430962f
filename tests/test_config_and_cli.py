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

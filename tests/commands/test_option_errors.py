"""A value is checked once, by the configuration layer; its refusal reaches the user as one line naming the option.

Each option's text goes as it is to the layer that reads and checks it
(``dicetrace.params.make_config``, ``dicetrace.windows.get_window`` /
``get_res``); the ConfigError raised there, however deep, names its field,
and ``commands.options`` turns the field into the option: exit code 2, one
line, no traceback.
"""

from __future__ import annotations

import pickle

import pytest

from dicetrace.commands.options import FIELD_OPTIONS, option_line
from dicetrace.params import ConfigError, Numerics, make_config

IC = ["--ic", "1,2,3,4,5,6"]
HOME3 = ["--window", "home", "--res", "3"]


@pytest.mark.parametrize(
    "command, args, line",
    [
        # tol: read and checked by make_config / Numerics, nowhere else
        ("simulate", [*IC, "--tol", "abc"], "--tol: tolerance tol must be a number in [1e-14, 1), got 'abc'"),
        ("simulate", [*IC, "--preset", "physical", "--tol", "1e-20"],
         "--tol: tolerance tol must be a number in [1e-14, 1), got '1e-20'"),
        ("simulate", [*IC, "--tol", "1e-5"], "--tol '1e-5' (contact-adaptive, contact-dop853, contact-tsit5 only) "
                                             "has no effect on semi-implicit-euler, whose steps are fixed"),
        ("scan", [*HOME3, "--preset", "physical", "--tol", "0"],
         "--tol: tolerance tol must be a number in [1e-14, 1), got '0'"),
        ("record", ["--slice", "seed", "--at", "0.05,0.05", "--preset", "physical", "--tol", "1"],
         "--tol: tolerance tol must be a number in [1e-14, 1), got '1'"),
        ("simulate", [*IC, "--preset", "physical", "--tol-growth", "-1"],
         "--tol-growth: tolerance growth tol_growth must be a number in [0, 1000] (1/s), got '-1'"),
        # preset: get_preset, once a command
        ("simulate", [*IC, "--preset", "moon"], "--preset: unknown preset 'moon' (choose from seed, physical)"),
        ("scan", [*HOME3, "--preset", "moon"], "--preset: unknown preset 'moon' (choose from seed, physical)"),
        ("record", ["--ic", "1,2,3,4,5,6", "--preset", "moon"], "--preset: unknown preset 'moon'"),
        ("explore", ["--preset", "moon", "--no-browser"], "--preset: unknown preset 'moon'"),
        # the other Numerics fields
        ("simulate", [*IC, "--dt", "-0"], "--dt: time step dt must be a finite number > 0, got '-0'"),
        ("simulate", [*IC, "--t-max", "1e-300"], "--t-max 1e-300 with --dt 0.001 (the default): time step dt"),
        ("simulate", [*IC, "--integrator", "magic"], "--integrator: unknown integrator 'magic'"),
        ("scan", [*HOME3, "--set", "gamma=-1"], "--set: preset 'seed': damping gamma must be >= 0, got -1.0"),
        # the die's body: --die and --load read in commands.options, their values checked with the preset
        ("simulate", [*IC, "--preset", "physical", "--die", "2,2"], "--die needs three sides in cm, X,Y,Z"),
        ("simulate", [*IC, "--preset", "physical", "--die", "2,0,2"], "--die needs three sides > 0 cm"),
        ("record", [*IC, "--preset", "physical", "--load", "0.3"], "--load needs W@X,Y,Z"),
        ("simulate", [*IC, "--preset", "physical", "--load", "1.2@0,0,0"], "--load needs a share W of the mass in [0, 1)"),
        ("simulate", [*IC, "--preset", "physical", "--load", "0.2@0,0,-1.5"],
         "--load: preset 'physical': load_cm (0.0, 0.0, -1.5) lies outside the box of half-extents (1.0, 1.0, 1.0)"),
        ("simulate", [*IC, "--die", "2,2,1"], "--integrator: preset 'seed' is no uniform cube"),
        # window: get_window
        ("scan", ["--window", "0,1,1,0", "--res", "3"], "--window: the y range must have y1 > y0 (negative width)"),
        ("scan", ["--sample", "random", "--n", "3", "--box", "atlantis"], "--box: unknown window 'atlantis'"),
        ("scan", ["--slice", "seed3", "--window", "home", "--z", "0.1,0", "--res", "3"],
         "--z: the z range must have z1 > z0 (negative width)"),
        ("explore", ["--window", "1,1,0,1", "--no-browser"], "--window: the x range must have x1 > x0 (zero width)"),
        # res: get_res
        ("scan", ["--window", "home", "--res", "2.5"], "--res: resolution must be whole numbers, N or NX,NY, got '2.5'"),
        ("scan", ["--slice", "seed3", "--window", "home", "--z", "0,1", "--res", "3,3"],
         "--res: resolution needs 3 numbers NX,NY,NZ"),
        ("explore", ["--res", "x", "--no-browser"], "--res: resolution must be whole numbers, N or NX,NY, got 'x'"),
        # device: dicetrace.devices.check_device (a DeviceError, mapped as a ConfigError is)
        ("scan", [*HOME3, "--device", "gpu"], "--device: device must be one of cpu, cuda, auto, got 'gpu'"),
        ("explore", ["--device", "CUDA", "--no-browser"], "--device: device must be one of cpu, cuda, auto, got 'CUDA'"),
    ],
)
def test_a_value_refused_deep_in_the_configuration_is_one_line_naming_the_option(
        tmp_path, dicetrace_cli, assert_one_line_error, command, args, line):
    extra = ["--out", "s", "-q"] if command == "scan" else ["--out", "r.rrd"] if command == "record" else []
    res = dicetrace_cli(command, *args, *extra, cwd=tmp_path)
    got = assert_one_line_error(res)
    assert got.startswith("dicetrace: error: " + line), got
    assert list(tmp_path.iterdir()) == []  # nothing written


def _definition_on(device):
    from dicetrace.ics import Grid
    from dicetrace.scan import ScanDefinition

    return ScanDefinition(Grid("seed", "home", 2), make_config("seed"), 4, device=device)


@pytest.mark.parametrize(
    "make, line",
    [
        (lambda: Numerics(tol=0.0), "--tol: tolerance tol"),
        (lambda: Numerics(tol_growth=1e9), "--tol-growth: tolerance growth"),
        (lambda: make_config("moon"), "--preset: unknown preset 'moon'"),
        (lambda: make_config(dt_s="auto", integrator="forward-euler", t_max_s=1e9), "--dt auto: forward-euler needs"),
        (lambda: Numerics(dt_s=2.0, t_max_s=1.0), "--t-max 1 with --dt 2: time step dt (2.0 s) is longer"),
        (lambda: _definition_on("auto"), "--device must be 'cpu' or 'cuda: <GPU name>' (a resolved device), got 'auto'"),
    ],
)
def test_the_option_is_found_by_the_errors_field_not_its_text(make, line):
    with pytest.raises(ConfigError) as exc:
        make()
    assert set(exc.value.fields) <= set(FIELD_OPTIONS)
    assert option_line(exc.value, {"--dt": "2", "--t-max": "1"}).startswith(line)
    same = pickle.loads(pickle.dumps(exc.value))  # crosses a process boundary (a Dask worker) whole
    assert (same.fields, same.message) == (exc.value.fields, exc.value.message)


def test_one_reader_of_each_value_in_the_commands():
    """The commands hold no check of their own for tol, the preset, a window or a resolution."""
    from pathlib import Path

    import dicetrace.commands as commands

    own = {"options.py", "scan.py", "simulate.py", "record.py", "explore.py", "_common.py"}
    for path in sorted(Path(commands.__file__).parent.glob("*.py")):
        if path.name not in own:
            continue
        text = path.read_text()
        for sign in ("TOL_MIN <=", "TOL_GROWTH_MAX", "def _parse_res", "def parse_positive", "in msg"):
            assert sign not in text, (path.name, sign)


def test_simulate_and_record_declare_their_shared_options_once():
    """``--slice`` and the model options of ``simulate`` and ``record`` are the annotations of ``commands.options``:
    the same flag, help text and default (None: the configuration layer's) in both commands."""
    import typer.main

    from dicetrace.cli import app
    from dicetrace.commands import options

    shared = {"--slice": options.SLICE_HELP, "--integrator": options.INTEGRATOR_HELP, "--dt": options.DT_HELP,
              "--t-max": options.T_MAX_HELP, "--tol": options.TOL_HELP, "--tol-growth": options.TOL_GROWTH_HELP}
    group = typer.main.get_command(app)
    for command in ("simulate", "record"):
        params = {p.opts[0]: p for p in group.commands[command].params}
        for flag, text in shared.items():
            assert params[flag].help == text and params[flag].default is None, (command, flag)

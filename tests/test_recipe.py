"""One recipe, one pipeline (issue 8): generated views, knobs that act or say why, app = CLI pixel for pixel."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import build_parser, main
from spikeview.errors import ParameterError
from spikeview.recipe import BY_KEY, PARAMS, Recipe
from test_gui_model import Ctx  # the worker's job context, as the app's jobs see it


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A small simulated chromatic capture (realistic noise) written as a plain .dat with its sidecar."""
    from spikeview.io import write_plain
    from spikeview.sim.demo import demo_capture

    d = tmp_path_factory.mktemp("cap")
    cap = demo_capture(size=32, n_ticks=120, seed=2)
    path = d / "c.dat"
    write_plain(path, cap.read(0, cap.n_frames), cfa=cap.cfa)
    return path


# ------------------------------------------------------------------------------ generated views
def test_every_flag_and_control_is_generated_from_the_one_table():
    from spikeview.session.model import SPECS

    sub = next(a for a in build_parser()._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    options = {o for a in sub.choices["reconstruct"]._actions for o in a.option_strings}
    for p in PARAMS:
        if p.flag:
            assert p.flag in options, p.flag
        if p.key:
            spec = SPECS[p.key]
            assert (spec.label, spec.help, spec.maximum) == (p.label, p.help, p.hi), p.path
            assert spec.validate(spec.default) == spec.default
    # one home: every default comes from the recipe's dataclasses
    assert SPECS["k"].default == Recipe().guided.k and SPECS["window"].default == Recipe().classical.window


def test_one_meaning_per_name_and_one_home_for_shared_fields(tmp_path):
    r = Recipe().with_values({"classical.window": 12, "classical.demosaic": "menon2007", "classical.colour_cast": False})
    assert (r.guided.window, r.guided.demosaic, r.guided.use_cast) == (12, "menon2007", False)
    d = r.to_dict()
    assert not {"window", "demosaic", "eta", "alpha", "use_cast"} & set(d["guided"]) and "method" not in d["classical"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[classical]\nwindow = 10\n[guided]\nwindow = 12\n")
    with pytest.raises(ParameterError, match="one home"):
        Recipe.load(bad)
    (tmp_path / "empty.toml").write_text("")
    with pytest.raises(ParameterError, match="empty"):
        Recipe.load(tmp_path / "empty.toml")


@pytest.mark.parametrize("argv, words", [
    (["--s", "-1"], "--s = -1 is out of range"),
    (["--window", "0"], "--window = 0 is out of range"),
    (["--levels", "2.5"], None),  # argparse: not an integer
    (["--t-start", "0.5"], "--t-start = 0.5 is out of range"),
])
def test_flag_errors_name_the_flag(capture, tmp_path, capsys, argv, words):
    code = None
    try:
        code = main(["reconstruct", str(capture), "--method", "guided", "--out", str(tmp_path / "x.npy"), *argv])
    except SystemExit as e:  # argparse's own usage error
        code = e.code
    err = capsys.readouterr().err
    assert code in (1, 2) and "Traceback" not in err and "this is a bug" not in err
    if words:
        assert words in err and "GuidedConfig" not in err
    assert not (tmp_path / "x.npy").exists()


def test_guided_flags_with_a_classical_method_say_they_are_ignored(capture, tmp_path, capsys):
    assert main(["reconstruct", str(capture), "--method", "tfp", "--at", "60", "--k", "3", "--out", str(tmp_path / "t.npy")]) == 0
    assert "--k applies to --method guided only" in capsys.readouterr().err


# ------------------------------------------------------------------------------------- knobs
def _run(capture, **guided):
    """One guided window of the capture with the recipe's defaults and ``guided`` changes; returns (frame, knobs)."""
    from spikeview.guided.knobs import knob_status
    from spikeview.guided.plan import make_plan
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, reconstruct_windows

    recipe = Recipe().with_values({"run.method": "guided", **{f"guided.{k}": v for k, v in guided.items()}})
    with open_source(capture) as src:
        state = prepare_sequence(src, recipe)
        from spikeview.guided.observation import Observation

        obs = Observation.from_source(src, 60, recipe.guided.window, alpha=state.alpha, eta=recipe.guided.eta, radius=0)
        knobs = knob_status(recipe.guided, make_plan(obs, recipe.guided))
        frame = next(reconstruct_windows(src, [60], recipe, state, sampler=GuidedSampler(recipe.guided)))
    return frame, knobs


def _moved(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.float64) - b).mean())


#: "visible": a mean absolute change of at least 1/255 of full scale
VISIBLE = 1.0 / 255.0


def test_s_acts_under_the_default_hqs_rule(capture):
    full, knobs = _run(capture)
    assert knobs["guided.s"] is None
    half, _ = _run(capture, s=0.2)
    assert _moved(full, half) > VISIBLE
    none, knobs0 = _run(capture, data_steps=0)
    assert "data_steps = 0" in knobs0["guided.s"]
    assert np.array_equal(none, _run(capture, data_steps=0, s=0.2)[0])  # the reason is true


def test_k_says_why_it_is_inert_with_q_off_and_acts_with_q_on(capture):
    a, knobs = _run(capture, k=1.0)
    assert knobs["guided.k"] is not None and "Q is off" in knobs["guided.k"]
    assert np.array_equal(a, _run(capture, k=400.0)[0])  # inert indeed
    on1, knobs_on = _run(capture, quantise=True, k=5.0)
    assert knobs_on["guided.k"] is None
    assert _moved(on1, _run(capture, quantise=True, k=200.0)[0]) > VISIBLE


def test_levels_act(capture):
    a, knobs = _run(capture, levels=0)
    assert knobs["guided.levels"] is None
    assert _moved(a, _run(capture, levels=2)[0]) > VISIBLE


def test_t_start_acts_above_the_datas_noise_and_says_why_below(capture):
    a, knobs = _run(capture, t_start=0.29)
    assert knobs["guided.t_start"] is None
    assert _moved(a, _run(capture, t_start=0.2)[0]) > VISIBLE / 4
    # with the prior told 10x the noise, any t_s below it adds nothing: the plan says so, and it is true
    low, knobs_low = _run(capture, t_start=0.05, sigma_scale=10.0)
    assert "exceeds t_s" in knobs_low["guided.t_start"]
    assert np.array_equal(low, _run(capture, t_start=0.02, sigma_scale=10.0)[0])


def test_the_apps_controls_are_disabled_with_the_reason():
    from spikeview.session.jobs import PreviewRequest, degradation_job
    from spikeview.session.model import Session
    from spikeview.sim.demo import demo_capture

    cap = demo_capture(size=32, n_ticks=60)
    s = Session()
    from spikeview.session.core import memory_stream

    s.open_stream(memory_stream(cap, "demo"))
    s.set_tick(30)
    view = degradation_job(PreviewRequest(s.source, 30, dict(s.params), None, recipe=s.recipe()), Ctx())
    assert view.knobs["guided.k"] and "Q is off" in view.knobs["guided.k"] and view.knobs["guided.levels"] is None
    s.set("quantise", "on")
    view = degradation_job(PreviewRequest(s.source, 30, dict(s.params), None, recipe=s.recipe()), Ctx())
    assert view.knobs["guided.k"] is None and "quantise  on" in view.plan and view.quantise


# ------------------------------------------------------------------------------- equivalence
def _app_session(capture, **values):
    from spikeview.session import core
    from spikeview.session.model import Session

    s = Session()
    s.open_stream(core.open_file(capture))
    s.update_params(values)
    return s


@pytest.mark.parametrize("method, values", [
    ("tfp", {"window": 8, "demosaic": "bilinear", "eta": 1.5}),
    ("guided", {"steps": 2, "s": 0.5, "levels": 1, "quantise": "on", "k": 20.0}),
])
def test_a_recipe_saved_by_the_app_gives_the_cli_the_apps_pixels(capture, tmp_path, method, values):
    from spikeview.session import jobs
    from spikeview.session.presets import save_preset, session_recipe

    s = _app_session(capture, export_method=method, export_range="marked", **values)
    s.set_mark_in(40)
    s.set_mark_out(75)
    recipe = session_recipe(s)
    ticks = jobs.export_ticks(recipe, s.n_frames)
    assert len(ticks) >= 2
    alpha, _note, _white, _said, _reach = jobs.alpha_job(s.source, recipe, Ctx())
    app_out = tmp_path / "app.npy"
    jobs.export_job(jobs.ExportRequest(s.source, str(capture), ticks, recipe, alpha, app_out), Ctx())
    preset = save_preset(s, tmp_path / "app.toml")
    cli_out = tmp_path / "cli.npy"
    assert main(["reconstruct", str(capture), "--preset", str(preset), "--out", str(cli_out)]) == 0
    a, b = np.load(app_out), np.load(cli_out)
    assert a.shape == b.shape and a.shape[0] == len(ticks)
    assert np.array_equal(a, b)


def test_loading_a_preset_and_saving_it_back_changes_no_field(capture, tmp_path):
    from spikeview.config import load_toml
    from spikeview.session.presets import load_preset, save_preset

    s = _app_session(capture)
    s.set_tick(50)
    first = save_preset(s, tmp_path / "first.toml")
    # fields without a control, and controls moved away from their defaults
    import tomli_w

    data = load_toml(first)
    data["guided"].update(data_steps=2, lam=3.5, zeta=0.25, k=33.0)
    edited = tmp_path / "edited.toml"
    edited.write_text(tomli_w.dumps(data))
    t = _app_session(capture)
    t.set_tick(50)
    load_preset(t, edited)
    again = save_preset(t, tmp_path / "again.toml")
    assert load_toml(again) == load_toml(edited)
    assert t.get("k") == 33.0 and t.recipe().guided.data_steps == 2


def test_session_values_map_to_recipe_paths_both_ways():
    from spikeview.session.model import Session, from_recipe_value, to_recipe_value

    s = Session()
    r = s.recipe()
    for key, p in BY_KEY.items():
        assert to_recipe_value(key, from_recipe_value(key, r.get(p.path))) == r.get(p.path), key
    s.set("quantise", "off")
    assert s.recipe().guided.quantise is False


def test_readme_and_the_apps_help_describe_every_knob_with_its_unit():
    from pathlib import Path

    from spikeview.recipe import help_rows, markdown_table

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = readme.split("<!-- params:start -->\n", 1)[1].split("\n<!-- params:end -->", 1)[0]
    assert block == markdown_table(), "README's parameter table is stale: paste spikeview.recipe.markdown_table()"
    rows = {path: text for path, _flag, _label, text in help_rows()}
    assert "ticks" in rows["classical.window"] and "fraction of full scale" in rows["guided.t_start"]
    for knob in ("guided.s", "guided.k", "guided.levels", "guided.t_start"):
        assert rows[knob].count(". ") <= 2  # one sentence, then the default


def test_the_shipped_fast_preset_is_a_valid_recipe():
    from pathlib import Path

    fast = Recipe.load(Path(__file__).resolve().parents[1] / "resources" / "presets" / "guided-fast.toml")
    assert fast.run.method == "guided" and fast.guided.steps == 3
    assert fast.guided.t_start == Recipe().guided.t_start  # everything else at the defaults


def test_the_apps_guided_metrics_compare_like_with_like():
    """The app scores its guided run at the sampler's exposure against the aligned ground truth (a unit
    mix-up once read 6 dB where the frame was fine)."""
    from spikeview.session import core, jobs
    from spikeview.session.model import Session

    st = core.demo_stream(size=48, n_ticks=120)
    s = Session()
    s.open_stream(st)
    s.set_tick(60)
    alpha, _note, white, _said, _reach = jobs.alpha_job(st.source, s.recipe(), Ctx())
    res = jobs.guided_job(jobs.GuidedRequest(st.source, 60, dict(s.params), alpha, None, st.ground_truth, 1, s.recipe()),
                          Ctx())
    assert res.psnr > 20.0 and res.ssim > 0.6, (res.psnr, res.ssim)


def test_every_app_parameter_has_a_control_or_says_it_is_preset_only():
    """Issue 27: a parameter the app holds has a control in a panel (a Param widget or the weights field), or is
    listed in recipe.PRESET_ONLY with its reason, which the README's table prints."""
    import pathlib
    import re

    from spikeview.recipe import PARAMS, PRESET_ONLY, markdown_table

    gui = "\n".join(p.read_text(encoding="utf-8") for p in pathlib.Path(__file__).parents[1].joinpath("spikeview", "gui").rglob("*.py"))
    missing = []
    for p in PARAMS:
        if not p.key or p.path in PRESET_ONLY:
            continue
        widget = re.search(r'Param\w*\(\s*(?:self\.)?session,\s*"' + re.escape(p.key) + '"', gui)
        if not widget and not re.search(r'session\.set\("' + re.escape(p.key) + '"', gui):
            missing.append(p.path)
    assert missing == [], f"app parameters without a control and not marked preset-only: {missing}"
    table = markdown_table()
    for path, why in PRESET_ONLY.items():
        assert f"preset only: {why}" in table and any(q.path == path for q in PARAMS)

"""Discovery beyond the vocabulary: hidden effects that no named cause covers are found as formulas;
no effect, or an effect a named cause covers, gives no discovered term.

The truths are written independently of the `Discovered` term: `JointSpring` (a named-style term
outside the vocabulary) and a test-local position-periodic force. Both are diagnosed end to end
(`diagnose`, and `dynax diagnose` for the linear axis), so the search, the refit through
simulation and the held-out test all have to work.
"""

import json
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dynax import (
    AbstractJointTerm,
    Acrobot,
    CoulombFriction,
    default_candidates,
    diagnose,
    Extended,
    JointSpring,
    LinearAxis,
    save_trajectory,
    Selection,
    Trajectory,
)
from dynax.internal import cli_main, DiscoverySearch, propose
from dynax.synthetic import demo_data, DEMO_TRUTH_PHYSICAL, Multisine, synthetic_trajectory

pytestmark = pytest.mark.heavy  # end-to-end runs of a minute or more


ACROBOT_BASE = ("theta1", "theta2", "theta3", "theta4", "theta5", "theta6", "theta7")


class _PositionPeriodicForce(AbstractJointTerm):
    """A force A sin(2 pi q / period + phase): a screw's pitch error or cogging, hidden in the test's truth."""

    joint: int = eqx.field(static=True)
    coefficient: jax.Array
    period: float = eqx.field(static=True)
    phase: float = eqx.field(static=True)
    cause: ClassVar[str] = "position_periodic_force"
    prefix: ClassVar[str] = "A"
    neutral: ClassVar[float] = 0.0
    sign: ClassVar[int] = 0

    def force(self, q, dq):
        return self.coefficient * jnp.sin(2 * jnp.pi * q / self.period + self.phase)


AXIS = LinearAxis(coulomb=jnp.asarray(20.0), offset=jnp.asarray(-3.0))  # the EMPS structure


def _axis_records(amplitude, *, period=0.05, seed=5):
    truth = Extended(AXIS, (_PositionPeriodicForce(0, jnp.asarray(amplitude), period, 0.7),))
    run = synthetic_trajectory(
        truth,
        duration=30.0,
        dt=0.01,
        seed=seed,
        excitation=Multisine(amplitude=60.0),
        noise=(1e-5, 1e-3),
        system_name="linear_axis",
    )
    k = 2001
    cut = lambda a, b, name: Trajectory(
        run.ts[a:b],
        run.xs[a:b],
        run.us[a:b],
        run.state_names,
        run.input_names,  # noqa: E731
        "linear_axis",
        name,
    )
    return cut(0, k, "run1.csv"), cut(k, len(run.ts), "run2.csv")


# --- the acrobot's hidden joint spring, end to end ------------------------------------------------


# The held-out run is 30 s, not the demo's 10 s. The held-out test's degrees of freedom do not grow
# with the record (the reference horizon is allowed up to a twentieth of the held-out time, and the
# windows' correlation length grows with it, so each run gives about 3 * 20 / 8 - 1 of them at most),
# but on the demo's 10 s run the refitted spring's window differences also vary slowly with the
# excitation (correlation length twice the overlap): 73 % gain, p = 0.064 there; 87 %, p = 0.016 with
# 20 s; 30 s gives the spring's gain room to dominate that variation (docs/diagnosis.md, "Discovery").
SPRING_VALIDATION_S = 30.0


@pytest.fixture(scope="module")
def spring_report():
    _, train, validation = demo_data(JointSpring(1, 1.5), seed=41, validation_s=SPRING_VALIDATION_S)
    return diagnose(Acrobot(), train, validation)


def test_hidden_joint_spring_is_discovered_with_its_stiffness(spring_report):
    j = spring_report.to_json()
    discovered = [f for f in j["findings"] if f["cause"] == "discovered"]
    assert len(discovered) == 1, j["findings"]
    f = discovered[0]
    assert f["where"] == "q2" and f["features"] == ["q2"], f
    stiffness = -f["coefficients"]["q2"]
    assert abs(stiffness / 1.5 - 1) < 0.10, stiffness
    assert f["gain"] >= 0.5
    assert "joint spring" in f["readings"][0]
    assert f["formula"].startswith("tau_q2 += -1.")
    assert 0 < f["std_errors"]["q2"] < 0.1 * stiffness
    assert j["verdict"] == "explained", j["structure"]
    assert j["gain"] >= 0.5


def test_discovered_terms_are_reported_apart_from_named_causes(spring_report):
    md = spring_report.to_markdown()
    assert "## Discovered terms (beyond the vocabulary)" in md
    assert md.index("## Causes") < md.index("## Discovered terms")
    assert "`tau_q2 += -1." in md
    j = spring_report.to_json()
    assert j["discovery"]["kept"] and j["discovery"]["proposals"][0]["features"] == ["q2"]
    assert any(name.startswith("c_q2[") for name in j["extended"]["parameters"])


@pytest.mark.slow  # about 30 s
def test_without_discovery_the_spring_stays_unexplained(spring_report):
    # The same structure with the search switched off: the honest `unexplained` of the vocabulary alone.
    j = spring_report.to_json()
    assert j["structure"]["nominal"]["significant"]
    _, train, validation = demo_data(JointSpring(1, 1.5), seed=41, validation_s=SPRING_VALIDATION_S)
    off = diagnose(Acrobot(), train, validation, selection=Selection(discovery=False, max_terms=1)).to_json()
    assert off["verdict"] == "unexplained"
    assert not any(f["cause"] == "discovered" for f in off["findings"])
    assert "discovery" not in off


# --- the search on its own: no false discoveries, named causes win -----------------------------


def _acrobot_search(term, seed, *, named=True, refit=ACROBOT_BASE):
    _, train, _ = demo_data(term, seed=seed)
    system = Acrobot.from_physical(**DEMO_TRUTH_PHYSICAL)
    vocabulary = [t.label(system) for t in default_candidates(system)] if named else []
    return propose(system, [train], DiscoverySearch(refit=refit, vocabulary=vocabulary))


def test_the_search_in_known_mode_with_nothing_refitted():
    # Known mode refits nothing: no direction is projected out, and the features are used as evaluated
    # (this crashed on a read-only array, `dynax diagnose --mode known` on the DFKI runs).
    blind = [p for p in _acrobot_search(CoulombFriction(1, 0.22), seed=11, named=False, refit=()) if p.features]
    assert [(p.channel, [f.kind for f in p.features]) for p in blind] == [(1, ["sign"])]


@pytest.mark.parametrize("seed", [12, 13])
def test_no_hidden_effect_gives_no_proposal_on_the_acrobot(seed):
    assert [p for p in _acrobot_search(CoulombFriction(1, 0.0), seed) if p.features] == []


def test_no_hidden_effect_gives_no_proposal_on_the_axis():
    train, _ = _axis_records(0.0)
    vocabulary = [t.label(AXIS) for t in default_candidates(AXIS)]
    assert [
        p
        for p in propose(AXIS, [train], DiscoverySearch(refit=("mass", "viscous"), vocabulary=vocabulary))
        if p.features
    ] == []


def test_a_named_cause_wins_over_the_equivalent_discovered_formula():
    # Without a vocabulary the search finds the hidden Coulomb friction as sign(dq2) at the elbow ...
    blind = [p for p in _acrobot_search(CoulombFriction(1, 0.22), seed=11, named=False) if p.features]
    assert [(p.channel, [f.kind for f in p.features]) for p in blind] == [(1, ["sign"])]
    # ... and with it, the named cause wins: nothing is proposed, and the search says whose it is.
    proposals = _acrobot_search(CoulombFriction(1, 0.22), seed=11)
    assert [p for p in proposals if p.features] == []
    assert any("coulomb_friction@q2" in p.deferred for p in proposals)


# --- the linear axis's position-periodic force, through the command line ----------------------------


@pytest.fixture(scope="module")
def periodic_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("periodic")
    train, validation = _axis_records(10.0)
    save_trajectory(train, folder / "run1.csv")
    save_trajectory(validation, folder / "run2.csv")
    (folder / "nominal.json").write_text(
        json.dumps({"parameters": {"mass": 90.0, "viscous": 190.0, "coulomb": 20.0, "offset": -3.0}})
    )
    return folder


# The nominal's viscous coefficient (190) is 7 % off the truth's (203.5). The CLI's default refit keeps it
# (the friction candidates test it), and the viscous candidate alone, judged against a model whose error the
# periodic force dominates, is 15 % better at p = 0.03: not selected; after discovery no vocabulary round
# follows, so the verdict would be `unexplained` (discovery 55 %, structure left in dq). This test is about the
# search, so it refits the viscous coefficient with the mass, as a user who doubts it would.
def _cli(folder, out, *extra):
    return cli_main(
        [
            "diagnose",
            "linear_axis",
            str(folder / "run1.csv"),
            "--validation",
            str(folder / "run2.csv"),
            "--nominal",
            str(folder / "nominal.json"),
            "--refit",
            "mass,viscous",
            "--reference-horizon",
            "0.5",
            "--out",
            str(out),
            *extra,
        ]
    )


@pytest.mark.slow  # about 40 s; the quick suite keeps the hidden spring's discovery
def test_cli_discovers_a_position_periodic_force_with_its_period(periodic_files, tmp_path, capsys):
    assert _cli(periodic_files, tmp_path / "on") == 0
    report = json.loads((tmp_path / "on" / "report.json").read_text())
    discovered = [f for f in report["findings"] if f["cause"] == "discovered"]
    assert len(discovered) == 1, report["findings"]
    f = discovered[0]
    assert f["where"] == "q" and all("2π q/" in name for name in f["features"]), f
    assert abs(f["period"] / 0.05 - 1) < 0.05
    assert abs(np.hypot(*f["coefficients"].values()) / 10.0 - 1) < 0.1  # amplitude 10 N
    assert f["gain"] >= 0.5
    assert "position-periodic force" in f["readings"][0]
    assert report["verdict"] == "explained"
    assert "Discovered (beyond the vocabulary) at q" in capsys.readouterr().out
    assert "## Discovered terms" in (tmp_path / "on" / "report.md").read_text()


@pytest.mark.slow  # about 40 s
def test_cli_no_discovery_switches_the_search_off(periodic_files, tmp_path):
    assert _cli(periodic_files, tmp_path / "off", "--no-discovery") == 0
    report = json.loads((tmp_path / "off" / "report.json").read_text())
    assert not any(f["cause"] == "discovered" for f in report["findings"])
    assert "discovery" not in report

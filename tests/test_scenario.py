from pathlib import Path

import numpy as np
import pytest

from hil.files.scenario import ScenarioError, load_scenario

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
PAPER_POSES = Path(__file__).resolve().parent / "data" / "paper-initial-poses.csv"   # the paper's

MINIMAL = """
name = "t"
duration = 5.0
[formation]
kind = "line"
[[robots]]
id = 1
pose = [0.0, 0.0, 0.0]
[[robots]]
id = 2
pose = [0.0, 5.0, 0.0]
"""


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_bundled_scenarios_load(path):
    sc = load_scenario(path)
    assert sc.name == path.stem and len(sc.ids) == len(sc.formation.offsets) >= 2


def test_paper_scenario_holds_the_papers_example():
    sc = load_scenario(SCENARIOS / "paper.toml")
    csv = np.loadtxt(PAPER_POSES, delimiter=",", skiprows=1)
    assert np.allclose(sc.poses, csv[:, 1:]) and list(sc.ids) == list(csv[:, 0])
    assert sc.obstacles.centers.tolist() == [[0.0, -20.0], [15.0, -5.0]]
    assert sc.obstacles.radii.tolist() == [3.0, 4.0]
    p, _ = sc.formation.reference(1.0)
    assert p[0].tolist() == pytest.approx([22.0, -16.0])
    assert sc.duration == 20.0 and sc.sensing_range == 8.0


def test_minimal_scenario_gets_the_defaults(tmp_path):
    sc = load_scenario(write(tmp_path, MINIMAL))
    assert sc.control.K == 4.0 and sc.robot.wheel_radius == 0.2 and len(sc.obstacles) == 0


@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace('duration = 5.0\n', ''), "duration: missing"),
    (lambda t: t.replace('duration = 5.0', 'duration = "long"'), "duration: expected"),
    (lambda t: t.replace('kind = "line"', 'kind = "blob"'), r"\[formation\] kind"),
    (lambda t: t.replace('pose = [0.0, 5.0, 0.0]', 'pose = [0.0, 5.0]'), r"robots\[1\].pose"),
    (lambda t: t.replace('id = 2', 'id = 1'), r"robots\[1\].id: duplicate"),
    (lambda t: t + '[control]\nK = -1.0\n', r"\[control\]: ControlParams.K"),
    (lambda t: t + '[control]\nperiod = 0.1\n', r"\[control\]: .*period 0.1"),
    (lambda t: t + '[control]\nKp = 1.0\n', r"\[control\]: unknown field\(s\) Kp"),
    (lambda t: t + '[[obstacles]]\ncenter = [1.0, 2.0]\n', r"obstacles\[0\].radius: missing"),
    (lambda t: t + '[sim]\nsensing_range = 3.0\n', r"\[sim\] sensing_range"),
    (lambda t: t + '[sim]\nplant = "magic"\n', r"\[sim\] plant"),
    (lambda t: 'colour = "red"\n' + t, r"top level: unknown field\(s\) colour"),
    (lambda t: t.replace('kind = "line"', 'kind = "line"\nspacing = 2.2'),
     "b \\+ hysteresis"),
    (lambda t: t.replace('kind = "line"', 'kind = "offsets"\noffsets = [[0.0, 0.0]]'),
     r"\[formation\] offsets"),
    (lambda t: t.replace('kind = "line"', 'kind = "line"\nassign = "nearest"'),
     r"\[formation\] assign: expected one of \['listed', 'shortest'\], got 'nearest'"),
    (lambda t: t.replace('[[robots]]\nid = 1\npose = [0.0, 0.0, 0.0]\n[[robots]]\nid = 2\n'
                         'pose = [0.0, 5.0, 0.0]\n', ''), r"\[\[robots\]\]: missing"),
])
def test_bad_fields_are_named_with_the_file(tmp_path, edit, field):
    path = write(tmp_path, edit(MINIMAL))
    with pytest.raises(ScenarioError, match=field) as exc:
        load_scenario(path)
    assert str(path) in str(exc.value)


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(write(tmp_path, "name = \n"))


def test_shortest_assignment_gives_each_robot_the_slot_of_least_squares(tmp_path):
    """Robots 1 and 2 start beside each other's listed places: listed, their paths cross;
    assigned, each takes the place in front of it, and the formation's places stay a set."""
    text = MINIMAL.replace('kind = "line"', 'kind = "offsets"\noffsets = [[10.0, 5.0], '
                           '[10.0, 0.0]]\nvelocity = [1.0, 0.0]')
    listed = load_scenario(write(tmp_path, text, "a.toml")).formation
    shortest = load_scenario(write(tmp_path, text.replace(
        "velocity", 'assign = "shortest"\nvelocity'), "b.toml")).formation
    assert listed.offsets.tolist() == [[10.0, 5.0], [10.0, 0.0]]
    assert shortest.offsets.tolist() == [[10.0, 0.0], [10.0, 5.0]]
    assert shortest.velocity == listed.velocity

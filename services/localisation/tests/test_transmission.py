"""The balise transmission: pass times from the antenna's history, faults decided by seed and
id alone, late telegrams, corrupt ids, malformed input named."""

from __future__ import annotations

import pytest

from localisation.transmission import BaliseFaults, Transmission, parse_telegrams

PASSES = "1000:100:120.0;1001:100:123.0"


def transmission(**faults: object) -> Transmission:
    t = Transmission(faults=BaliseFaults(**faults), antenna_offset_m=39.7)  # type: ignore[arg-type]
    t.start(0.0, 0.0)
    return t


def test_pass_time_is_when_the_antenna_was_over_the_balise() -> None:
    t = transmission()
    assert t.step(1.0, "", 50.0) == ("", "")  # antenna 39.7 -> 89.7
    telegrams, faults = t.step(2.0, PASSES, 100.0)  # antenna 89.7 -> 139.7
    assert faults == ""
    read = parse_telegrams(telegrams)
    assert [(r.balise_id, r.group_id) for r in read] == [(1000, 100), (1001, 100)]
    assert read[0].time_s == pytest.approx(1.0 + (120.0 - 89.7) / 50.0)
    assert read[1].time_s == pytest.approx(1.0 + (123.0 - 89.7) / 50.0)


def test_lost_group_gives_nothing_and_says_so() -> None:
    t = transmission(lost_groups=frozenset({100}))
    t.step(1.0, "", 50.0)
    assert t.step(2.0, PASSES, 100.0) == ("", "lost:1000:100;lost:1001:100")


def test_losses_depend_on_seed_and_id_alone() -> None:
    faults = BaliseFaults(loss_probability=0.5, seed=4)
    drawn = [faults.lost(b, 1) for b in range(1000, 1100)]
    assert drawn == [
        BaliseFaults(loss_probability=0.5, seed=4).lost(b, 1) for b in range(1000, 1100)
    ]
    assert 30 < sum(drawn) < 70
    assert drawn != [
        BaliseFaults(loss_probability=0.5, seed=5).lost(b, 1) for b in range(1000, 1100)
    ]
    groups = BaliseFaults(group_loss_probability=1.0)
    assert all(groups.lost(b, 7) for b in (1, 2, 3))


def test_late_group_arrives_late_with_a_late_time_stamp() -> None:
    t = transmission(late_groups=frozenset({100}), late_delay_s=2.0)
    t.step(1.0, "", 50.0)
    telegrams, faults = t.step(2.0, PASSES, 100.0)
    assert telegrams == "" and faults == "late:1000:100;late:1001:100"
    assert t.step(3.0, "", 150.0) == ("", "")
    read = parse_telegrams(t.step(4.0, "", 200.0)[0])
    assert read[0].time_s == pytest.approx(1.0 + (120.0 - 89.7) / 50.0 + 2.0)


def test_corrupt_telegram_carries_other_ids() -> None:
    t = transmission(corrupt_balises=frozenset({1001}))
    t.step(1.0, "", 50.0)
    telegrams, faults = t.step(2.0, PASSES, 100.0)
    assert faults == "corrupt:1001:100"
    read = parse_telegrams(telegrams)
    assert (read[0].balise_id, read[0].group_id) == (1000, 100)
    assert (read[1].balise_id, read[1].group_id) != (1001, 100)


def test_malformed_passes_and_probabilities_are_named() -> None:
    t = transmission()
    with pytest.raises(ValueError, match="'1000:100' is not id:group:distance"):
        t.step(1.0, "1000:100", 50.0)
    with pytest.raises(ValueError, match=r"loss_probability must be within 0\.\.1"):
        BaliseFaults(loss_probability=1.5)

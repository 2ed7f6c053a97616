"""The pacing floor of ``bench --node`` (`tools/bench/pacing_floor.py`): no ROS."""
from flexure_sim.tools.bench import pacing_floor


def test_every_paced_tick_is_counted_and_work_longer_than_the_period_misses_every_one():
    # 3 ms of work in a 2 ms period: each tick ends after the next one is due, on any machine.
    r = pacing_floor.run(500.0, 3000.0, 0.2, warmup=0.04)
    assert r["ticks"] == 100
    assert r["missed_ticks"] == 100 and r["missed_fraction"] == 1.0
    assert r["max_late_us"] >= 1000.0  # each tick starts >= 1 ms after its slot
    assert "missed 100 of 100 (100.000 %)" in pacing_floor.summary(r)


def test_the_command_line_prints_one_json_object(capsys):
    import json

    assert pacing_floor.main(["--rate", "200", "--work-us", "0", "--duration", "0.1",
                              "--warmup", "0", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["ticks"] == 20 and r["work_us"] == 0.0 and r["rate_hz"] == 200.0


def test_the_command_line_paces_with_the_wake_spin_asked_and_refuses_a_negative_one(capsys):
    import json

    import pytest

    assert pacing_floor.main(["--rate", "200", "--work-us", "0", "--duration", "0.1",
                              "--warmup", "0", "--wake-spin", "5e-05", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["wake_spin_s"] == 5e-05 and r["ticks"] == 20
    with pytest.raises(SystemExit) as exc:
        pacing_floor.main(["--wake-spin", "-1"])
    assert exc.value.code == 2
    assert "--wake-spin" in capsys.readouterr().err

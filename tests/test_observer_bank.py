"""The observer bank (experiments/engine/observer_bank.py) on real FMU runs: multi-rate feeding, missing
channels (NaN, valid flags, events), offline observers, unit conversion and unit mismatches.

The observers here are stubs that echo what they are fed, so every test can check the exact
samples, masks and rates against the recorded signals."""

from pathlib import Path

import numpy as np
import pytest

from helpers import installed_estimators
from railfmu.estimators.core.observer import Observer, OfflineObserver
from railfmu.experiments.engine.observer_bank import ObserverBank
from railfmu.fmus.cosim.masters import run
from railfmu.experiments.engine.recorder import ArrayRecorder
from railfmu.models.errors import UserError
from railfmu.fmus.ssp import read_system
from railfmu.fmus.ssp.xmltools import RF_NS as RF  # our annotation namespace


class Echo(Observer):
    """Echoes its last measurements (NaN where missing), the held known input, how often each
    channel was present and how many sample times it predicted over."""

    measurements = ("a", "b")
    inputs = ("v",)
    outputs = ("a", "b", "v", "n_a", "n_b", "predictions")
    units = {"a": "m/s2", "b": "rad/s", "v": "m", "n_a": "", "n_b": "", "predictions": ""}

    def _reset(self):
        self._z = np.full(2, np.nan)
        self._n = np.zeros(2)
        self._u = np.full(1, np.nan)
        self._pred = 0

    def _predict(self):
        self._pred += 1

    def _update(self, z, mask):
        self._z = np.where(mask, z, np.nan)
        self._n += mask

    def _estimate(self):
        return np.array([*self._z, self._u[0], *self._n, self._pred])


class EventEcho(Echo):
    event_driven = True


class Diverging(Echo):
    """Fails numerically at its 51st sample, as a filter whose covariance is lost would."""

    def _update(self, z, mask):
        super()._update(z, mask)
        if self.steps == 50:
            raise FloatingPointError("the covariance is not finite")


class RecordMean(OfflineObserver):
    """Offline: the mean of each measurement over the samples where it is present, and the
    number of samples, at every time of the record."""

    measurements = ("a", "b")
    outputs = ("mean_a", "mean_b", "n")
    units = {"a": "m/s2", "b": "rad/s", "mean_a": "m/s2", "mean_b": "rad/s", "n": ""}

    def _run(self, t, Z, U, mask):
        means = [Z[mask[:, j], j].mean() for j in range(2)]
        return np.tile([*means, len(t)], (len(t), 1))


#: the stubs by registered name, as a third party registers its estimators (entry points)
STUBS = {"stub_echo": "Echo", "stub_event_echo": "EventEcho", "stub_diverging": "Diverging",
         "stub_record_mean": "RecordMean"}
NAME = {cls: name for name, cls in STUBS.items()}


@pytest.fixture(autouse=True)
def stubs_registered(tmp_path, monkeypatch):
    """The stubs installed, for each test, as a distribution registering them."""
    monkeypatch.syspath_prepend(str(installed_estimators(
        tmp_path / "site", **{k: f"test_observer_bank:{v}" for k, v in STUBS.items()})))


def ssd(observers: str, step: float = 1e-3, stop: float = 0.2) -> str:
    """track -> wheelset -> sensors (no noise on 1-3; channel 4 pure noise held 5 ms), a
    StepSource 0 -> 1 at 0.1 s as a valid flag; the sensors' channel 1 in mm/s2 (an SSD unit)."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="bank" xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:rf="{RF}">
  <ssd:System name="bank">
    <ssd:Elements>
      <ssd:Component name="track" source="TrackIrregularity.fmu">
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="track"><ssv:Parameters>
            <ssv:Parameter name="psd_level"><ssv:Integer value="1"/></ssv:Parameter>
            <ssv:Parameter name="seed"><ssv:Integer value="3"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="wheelset" source="WheelsetLateral.fmu"/>
      <ssd:Component name="flag" source="StepSource.fmu">
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="flag"><ssv:Parameters>
            <ssv:Parameter name="initial_value"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="final_value"><ssv:Real value="1"/></ssv:Parameter>
            <ssv:Parameter name="step_time"><ssv:Real value="0.1"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="sensors" source="SensorNoise.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u_1" kind="input"><ssc:Real unit="mm/s2"/></ssd:Connector>
          <ssd:Connector name="y_1" kind="output"><ssc:Real unit="mm/s2"/></ssd:Connector>
          <ssd:Connector name="y_2" kind="output"><ssc:Real unit="rad/s"/></ssd:Connector>
          <ssd:Connector name="y_4" kind="output"><ssc:Real unit="m/s2"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="sensors"><ssv:Parameters>
            <ssv:Parameter name="sigma_4"><ssv:Real value="1"/></ssv:Parameter>
            <ssv:Parameter name="sample_period"><ssv:Real value="0.005"/></ssv:Parameter>
            <ssv:Parameter name="u_3"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="u_4"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="u_5"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="u_6"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="u_7"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="u_8"><ssv:Real value="0"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="track" startConnector="alignment_1" endElement="wheelset" endConnector="xi"/>
      <ssd:Connection startElement="track" startConnector="alignment_rate_1" endElement="wheelset" endConnector="xi_rate"/>
      <ssd:Connection startElement="wheelset" startConnector="ddy" endElement="sensors" endConnector="u_1"/>
      <ssd:Connection startElement="wheelset" startConnector="dpsi" endElement="sensors" endConnector="u_2"/>
    </ssd:Connections>
    <ssd:Annotations>
      <ssc:Annotation type="org.railfmu.observers"><rf:Observers>{observers}</rf:Observers></ssc:Annotation>
      <ssc:Annotation type="org.railfmu.recorder"><rf:Recorder>
        <rf:Record connector="wheelset.ddy"/><rf:Record connector="wheelset.dpsi"/>
      </rf:Recorder></ssc:Annotation>
    </ssd:Annotations>
  </ssd:System>
  <ssd:Units>
    <ssc:Unit name="mm/s2"><ssc:BaseUnit m="1" s="-2" factor="0.001"/></ssc:Unit>
  </ssd:Units>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}">
    <ssd:Annotations><ssc:Annotation type="org.railfmu.experiment"><rf:FixedStep stepSize="{step}"/></ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""


def observer(name="echo", cls="Echo", a="sensors.y_1", b="sensors.y_2", v="track.alignment_1", attrs="",
             valid="", truth='<rf:Truth name="a" connector="wheelset.ddy"/>') -> str:
    u = f'<rf:Input name="v" connector="{v}"/>' if v else ""
    return (f'<rf:Observer name="{name}" class="{NAME.get(cls, cls)}" {attrs}>'
            f'<rf:Measurement name="a" connector="{a}" {valid}/><rf:Measurement name="b" connector="{b}"/>'
            f'{u}{truth}</rf:Observer>')


def system_of(tmp_path, fmu_dir, observers: str, **kw):
    folder = tmp_path / "bank"
    folder.mkdir(exist_ok=True)
    (folder / "SystemStructure.ssd").write_text(ssd(observers, **kw))
    return read_system(folder, fmu_dirs=[fmu_dir])


def run_bank(system, out: Path | None = None):
    """The run through the Jacobi master with the recorder and the bank as sinks."""
    bank = ObserverBank(system, out / "estimates.csv" if out else None)
    rec = ArrayRecorder()
    res = run(system, "jacobi", sinks=[rec, bank], progress=False)
    assert res.complete
    return {c: res.data[:, j] for j, c in enumerate(res.columns)}, bank


def columns(bank, name):
    t, est = bank.arrays()
    obs = next(o for s, o in zip(bank.specs, bank.observers) if s.name == name)
    first = bank.columns.index(f"{name}.{obs.outputs[0]}")
    return {o: est[:, first + j] for j, o in enumerate(obs.outputs)}


def test_units_are_converted_and_rows_fed_at_every_step(fmu_dir, tmp_path):
    """mm/s2 on the sensor connector -> m/s2 in the observer (factor 1e-3): the wheelset's own
    ddy to rounding; rad/s unchanged bit for bit; the known input is the recorded alignment."""
    system = system_of(tmp_path, fmu_dir, observer())
    sig, bank = run_bank(system, tmp_path)
    e = columns(bank, "echo")
    n = len(sig["time"])
    assert n == 201
    np.testing.assert_allclose(e["a"], sig["wheelset.ddy"], rtol=1e-13, atol=0)
    assert np.array_equal(e["a"], 1e-3 * sig["sensors.y_1"])  # the affine map, exactly
    assert not np.array_equal(sig["sensors.y_1"], sig["wheelset.ddy"])  # the FMU sees mm/s2
    assert np.array_equal(e["b"], sig["wheelset.dpsi"])
    assert np.array_equal(e["v"], sig["track.alignment_1"])
    assert np.array_equal(e["predictions"], np.arange(n))
    m = bank.metrics(sig)["echo"]
    assert m["steps"] == n and m["skipped"] == 0 and m["partial"] == 0
    assert m["a"]["rms_error"] < 1e-13 * m["a"]["rms_truth"]
    header = (tmp_path / "estimates.csv").read_text().splitlines()[0]
    assert header == "time," + ",".join(f"echo.{o}" for o in Echo.outputs)


def test_multi_rate_observer_is_fed_at_its_period(fmu_dir, tmp_path):
    """A 5 ms observer in a 1 ms system: rows 0, 5, 10, ...; its estimate held in between."""
    system = system_of(tmp_path, fmu_dir, observer(attrs='samplePeriod="0.005"'))
    sig, bank = run_bank(system)
    e = columns(bank, "echo")
    k = np.arange(len(sig["time"]))
    held = 5 * (k // 5)
    assert np.array_equal(e["b"], sig["wheelset.dpsi"][held])
    assert np.array_equal(e["predictions"], k // 5)  # one 5 ms sample time per call
    assert bank.metrics(sig)["echo"]["steps"] == 41


def test_slow_observer_in_a_fast_system(fmu_dir, tmp_path):
    """A 10 s (GNSS-like) observer in a 0.1 s system: three samples in 25 s."""
    system = system_of(tmp_path, fmu_dir, observer(attrs='samplePeriod="10"'), step=0.1, stop=25)
    sig, bank = run_bank(system)
    e = columns(bank, "echo")
    assert bank.metrics(sig)["echo"]["steps"] == 3
    assert np.array_equal(e["predictions"][[0, 99, 100, 199, 200, 250]], [0, 0, 1, 1, 2, 2])
    assert np.array_equal(e["b"][[0, 150, 250]], sig["wheelset.dpsi"][[0, 100, 200]])
    with pytest.raises(UserError, match="samplePeriod 0.15 s is not a whole number of system steps"):
        ObserverBank(system_of(tmp_path, fmu_dir, observer(attrs='samplePeriod="0.15"'), step=0.1), None)


def test_valid_flag_masks_one_channel(fmu_dir, tmp_path):
    """``a`` bound to a flag that turns 1 at 0.1 s: missing before (b still updates), present after."""
    system = system_of(tmp_path, fmu_dir, observer(valid='valid="flag.y"'))
    sig, bank = run_bank(system)
    e = columns(bank, "echo")
    on = sig["flag.y"] != 0
    assert 0 < on.sum() < len(on) and not on[0] and on[-1]
    assert np.isnan(e["a"][~on]).all() and np.array_equal(e["a"][on], 1e-3 * sig["sensors.y_1"][on])
    assert np.array_equal(e["n_a"], np.cumsum(on)) and np.array_equal(e["n_b"], np.arange(1, len(on) + 1))
    m = bank.metrics(sig)["echo"]
    assert m["partial"] == (~on).sum() and m["skipped"] == 0


def test_event_driven_channels_arrive_when_they_change(fmu_dir, tmp_path):
    """Channel 4 of the sensors is noise held for 5 ms: as an event it arrives every 5th row;
    ``b`` (the yaw rate) changes at every row."""
    system = system_of(tmp_path, fmu_dir, observer(cls="EventEcho", a="sensors.y_4", truth=""))
    sig, bank = run_bank(system)
    e = columns(bank, "echo")
    y4 = sig["sensors.y_4"]
    changed = np.r_[True, y4[1:] != y4[:-1]]
    assert changed.sum() == 41  # 201 rows, a new noise sample every 5 ms
    assert np.array_equal(e["n_a"], np.cumsum(changed))
    assert np.array_equal(e["n_b"], np.arange(1, len(y4) + 1))


def test_nan_rows_skip_only_the_missing_channels(fmu_dir, tmp_path):
    """Recorded rows replayed into the bank with NaNs: one channel missing -> partial update,
    both missing -> prediction only; a NaN known input keeps the held one."""
    system = system_of(tmp_path, fmu_dir, observer(truth=""))
    sig, _ = run_bank(system)
    cols = ["time", *system.record]
    rows = np.column_stack([sig[c] for c in cols])
    rows[10, cols.index("sensors.y_1")] = np.nan
    rows[20:23, cols.index("sensors.y_1")] = np.nan
    rows[20:23, cols.index("sensors.y_2")] = np.nan
    rows[30, cols.index("track.alignment_1")] = np.nan
    bank = ObserverBank(system, None)
    bank.open(cols)
    bank.write_block(rows)
    bank.close(True)
    e = columns(bank, "echo")
    m = bank.metrics(sig)["echo"]
    assert (m["steps"], m["partial"], m["skipped"]) == (201, 1, 3)
    assert np.isnan(e["a"][10]) and e["b"][10] == sig["wheelset.dpsi"][10]
    assert np.array_equal(e["n_b"][[19, 22, 23]], [20, 20, 21])  # 20..22 predicted only
    assert e["v"][30] == sig["track.alignment_1"][29]  # held


def test_offline_observer_gets_the_whole_record(fmu_dir, tmp_path):
    obs = (observer() + observer(name="mean", cls="RecordMean", v="", attrs='offline="true"', valid='valid="flag.y"',
                                 truth='<rf:Truth name="mean_a" connector="wheelset.ddy"/>'))
    system = system_of(tmp_path, fmu_dir, obs)
    sig, bank = run_bank(system, tmp_path)
    on = sig["flag.y"] != 0
    t, X = bank.results["mean"]
    assert np.array_equal(t, sig["time"])
    assert X[0, 0] == np.mean(1e-3 * sig["sensors.y_1"][on]) and X[0, 1] == np.mean(sig["wheelset.dpsi"])
    assert X[0, 2] == len(t)
    csv = np.loadtxt(tmp_path / "estimates_mean.csv", delimiter=",", skiprows=1)
    assert np.array_equal(csv[:, 1:], X) and np.array_equal(csv[:, 0], t)
    assert bank.columns == [f"echo.{o}" for o in Echo.outputs]  # not in estimates.csv
    m = bank.metrics(sig)["mean"]
    assert m["offline"] is True and m["wall_time_s"] >= 0 and "mean_a" in m
    assert np.array_equal(bank.offline_estimates()["mean.n"], X[:, 2])


def test_offline_flag_must_match_the_class(fmu_dir, tmp_path):
    system = system_of(tmp_path, fmu_dir, observer(name="mean", cls="RecordMean", v="", truth=""))
    with pytest.raises(UserError, match=r"stub_record_mean is an offline estimator; declare it with offline=\"true\""):
        ObserverBank(system, None)


def test_unit_mismatch_is_one_line_naming_observer_channel_and_units(fmu_dir, tmp_path):
    system = system_of(tmp_path, fmu_dir, observer(a="wheelset.dpsi"))
    with pytest.raises(UserError) as info:
        ObserverBank(system, None)
    msg = str(info.value)
    assert "\n" not in msg
    assert ("Observer 'echo': measurement 'a' is in 'm/s2' (m s-2) but wheelset.dpsi is in 'rad/s' "
            "(s-1 rad): incompatible units") in msg
    system = system_of(tmp_path, fmu_dir, observer(a="sensors.y_3"))  # a connector without a unit
    with pytest.raises(UserError, match=r"measurement 'a' is in 'm/s2' but sensors.y_3 has no unit"):
        ObserverBank(system, None)
    system = system_of(tmp_path, fmu_dir, observer(v="wheelset.dpsi"))
    with pytest.raises(UserError, match=r"input 'v' is in 'm' \(m\) but wheelset.dpsi is in 'rad/s'"):
        ObserverBank(system, None)


def test_export_keeps_the_observer_declarations(fmu_dir, tmp_path):
    """samplePeriod, sampling, offline, valid flags and the units given on SSD connectors survive
    `railfmu export` (the .ssp is schema-valid and reads back to the same specs)."""
    from railfmu.fmus.ssp import validate_ssp, write_ssp

    obs = (observer(attrs='samplePeriod="0.005" sampling="event"', valid='valid="flag.y"')
           + observer(name="mean", cls="RecordMean", v="", attrs='offline="true"', truth=""))
    system = system_of(tmp_path, fmu_dir, obs)
    archive = write_ssp(system, tmp_path / "bank.ssp")
    assert validate_ssp(archive) == []
    again = read_system(archive)
    for a, b in zip(system.observers, again.observers, strict=True):
        assert (a.name, a.cls, a.measurements, a.inputs, a.valid, a.truth, a.period, a.event, a.offline) == \
               (b.name, b.cls, b.measurements, b.inputs, b.valid, b.truth, b.period, b.event, b.offline)
        assert {k: (u.name, u.exponents) for k, u in a.units.items()} == \
               {k: (u.name, u.exponents) for k, u in b.units.items()}
    assert again.observers[0].units["sensors.y_1"].factor == 1e-3  # mm/s2, defined in the exported ssd:Units
    ObserverBank(again, None)  # the unit checks pass on the exported system


def test_a_failing_observer_neither_ends_the_run_nor_loses_the_others(fmu_dir, tmp_path, capsys):
    """One estimator raising a numerical error mid-run: its estimates are NaN from that sample
    on, the others and the signals are complete, and the warning and metrics.json say why."""
    system = system_of(tmp_path, fmu_dir, observer() + observer(name="bad", cls="Diverging"))
    sig, bank = run_bank(system, tmp_path)
    good, bad = columns(bank, "echo"), columns(bank, "bad")
    assert np.isfinite(good["a"]).all() and len(sig["time"]) == 201
    assert np.array_equal(bad["b"][:50], good["b"][:50]) and np.isnan(bad["b"][50:]).all()
    m = bank.metrics(sig)
    assert m["bad"]["failed"] == "FloatingPointError at t = 0.05 s: the covariance is not finite"
    assert "failed" not in m["echo"]
    err = capsys.readouterr().err
    assert "Observer 'bad' failed (FloatingPointError at t = 0.05 s" in err and "Traceback" not in err


def test_a_switched_off_observer_is_not_built(fmu_dir, tmp_path):
    """`enabled=false` (a variant or --set): the bank builds, feeds and scores only the others;
    a class that could not even be imported is not touched."""
    obs = observer() + observer(name="off", cls="NoSuchClass", attrs="").replace(
        "</rf:Observer>", '<rf:Setting name="enabled" value="false"/></rf:Observer>')
    system = system_of(tmp_path, fmu_dir, obs)
    sig, bank = run_bank(system, tmp_path)
    assert [s.name for s in bank.specs] == ["echo"] and set(bank.estimators()) == {"echo"}
    assert set(bank.metrics(sig)) == {"echo"}
    on = system_of(tmp_path, fmu_dir, obs.replace("NoSuchClass", "stub_echo"))
    on.observers[1].settings["enabled"] = True  # as --set off.enabled=true: built, without the setting
    assert set(ObserverBank(on, None).estimators()) == {"echo", "off"}


def test_estimators_hand_the_finished_objects_to_the_study(fmu_dir, tmp_path):
    """After the run the bank hands each estimator object, online and offline, by name."""
    obs = observer() + observer(name="mean", cls="RecordMean", v="", attrs='offline="true"', truth="")
    sig, bank = run_bank(system_of(tmp_path, fmu_dir, obs))
    est = bank.estimators()
    assert isinstance(est["echo"], Echo) and isinstance(est["mean"], RecordMean)
    assert est["echo"].steps == len(sig["time"])


def test_settings_bound_to_parameters_reach_the_class(fmu_dir, tmp_path):
    """A setting bound to a component parameter is passed as that parameter's value."""
    obs = observer(name="p", truth="").replace(
        "</rf:Observer>", '<rf:Setting name="gain" parameter="sensors.sigma_4"/></rf:Observer>')
    system = system_of(tmp_path, fmu_dir, obs)
    assert ObserverBank(system, None).estimators()["p"].settings == {"gain": 1.0}  # the SSD binds sigma_4 = 1

"""Modbus links against the real fake device: TCP on loopback and RTU over a pty."""

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from fdi_daemon.io import modbus_map as mm
from fdi_daemon.io.links.base import LinkError, ReconnectingLink, make_link
from fdi_daemon.io.links.modbus_link import ModbusLink
from hil_sim.devices import SimulatedDevice, realtime_rig
from hil_sim.devices.modbus_server import ModbusDevice, RegisterImage
from hil_sim.devices.realtime import DEFAULT_SCENARIO, DeviceSample
from hil_sim.scenarios import scenario_from_dict, simulate


@pytest.fixture(scope="module")
def reference():
    """What the device must publish: the same scenario and seed simulated offline."""
    return simulate(scenario_from_dict(DEFAULT_SCENARIO), seed=2, duration_s=30.0)


def read_for(link, seconds, timeout_s=0.05):
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += link.read(timeout_s)
    return out


def assert_consecutive(samples):
    seqs = [s.seq for s in samples]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


def assert_equals_reference(samples, ref, scales=(1.0, 1.0, 1.0)):
    """Values as float32 (value / scale), times the scale as the header carries it (f32)."""
    f32 = [float(np.float32(x)) for x in scales]
    for s in samples:
        i = s.seq
        assert s.t == ref.t[i]
        assert s.v_in == float(np.float32(ref.v_in[i] / scales[0])) * f32[0]
        assert s.accel == float(np.float32(ref.accel[i] / scales[1])) * f32[1]


@pytest.mark.parametrize("transport", ["modbus-tcp", "modbus-rtu"])
def test_link_delivers_every_sample_once_as_simulated(transport, reference):
    with SimulatedDevice(transport, realtime_rig(seed=2)) as dev:
        link = make_link(dev.link_config)
        link.open()
        try:
            samples = read_for(link, 1.5)
        finally:
            link.close()
    assert len(samples) > 200
    assert_consecutive(samples)
    assert_equals_reference(samples, reference)
    assert link.counters()["samples_lost"] == 0
    assert link.header.fs_hz == 256 and link.header.fifo_depth == 256


def test_a_slow_poller_loses_nothing(reference):
    with SimulatedDevice("modbus-tcp", realtime_rig(seed=2)) as dev:
        link = make_link({**dev.link_config, "poll_interval_s": 0.25})
        link.open()
        samples = read_for(link, 1.6)
        link.close()
    assert_consecutive(samples)
    assert_equals_reference(samples, reference)
    c = link.counters()
    assert c["samples_lost"] == 0
    assert c["requests"] > c["polls"]  # the deeper FIFO slots were read


class _FifoThatGrowsBetweenRequests:
    """A client on the device's register image that publishes ``per_request`` new samples
    after answering each request, as a device does while a poll's requests are in flight."""

    def __init__(self, image, per_request):
        self.image, self.per_request, self.seq = image, per_request, 0

    def publish(self, n):
        self.image.publish(
            [
                DeviceSample(self.seq + i, 0.0, float(self.seq + i), 0.0, 0.0, False, False)
                for i in range(n)
            ]
        )
        self.seq += n

    def connect(self):
        return True

    def close(self):
        pass

    def read_input_registers(self, address, count, device_id):
        regs = [0] * self.image.input_size
        self.image.fill_inputs(regs, address, count)
        self.publish(self.per_request)
        return SimpleNamespace(registers=regs[address : address + count], isError=lambda: False)


@pytest.mark.parametrize("fifo_depth", [64, 256])
@pytest.mark.parametrize("per_request", [0, 1, 2, 3])
def test_a_poll_loses_nothing_while_the_fifo_fills_between_its_requests(per_request, fifo_depth):
    """The deeper reads of a poll follow the FIFO as it moves on, also before it is full."""
    rig = SimpleNamespace(fs_hz=256.0, fault_injected=False)
    client = _FifoThatGrowsBetweenRequests(RegisterImage(rig, fifo_depth=fifo_depth), 0)
    link = ModbusLink("modbus-tcp", "fake", lambda: client)
    link.open()
    client.publish(1)
    delivered = link.poll()  # seq 0: the FIFO is far from full, as just after device start
    client.per_request = per_request
    for behind in (17, 40, 29, fifo_depth // 2):  # with what moves on, less than the FIFO
        client.publish(behind)
        delivered += link.poll()
    seqs = [s.seq for s in delivered]
    assert seqs == list(range(seqs[-1] + 1))
    assert len(seqs) > 17 + 40 + 29 + fifo_depth // 2
    assert [s.v_in for s in delivered] == [float(s.seq) for s in delivered]
    assert link.counters()["samples_lost"] == 0


def test_a_poller_behind_the_fifo_shows_the_loss_as_a_seq_jump():
    rt = realtime_rig(seed=2)
    dev = ModbusDevice(rt, fifo_depth=32)
    host, port = dev.start_tcp()
    try:
        link = ModbusLink.tcp(host, port)
        link.open()
        first = []
        while not first:
            first = link.poll()
        time.sleep(0.6)  # ~150 samples: more than the FIFO holds
        second = link.poll()
        link.close()
    finally:
        dev.stop()
    lost = link.counters()["samples_lost"]
    assert lost > 0 and link.counters()["fifo_overruns"] == 1
    assert second[0].seq == first[-1].seq + 1 + lost
    assert_consecutive(second)
    assert 16 <= len(second) <= 32  # the whole FIFO, less what moved on between requests


def test_little_word_order_and_scaled_units(reference):
    scales = (1.0, 9.80665, 1e-3)  # accel published in g, position in mm
    rt = realtime_rig(seed=2)
    dev = ModbusDevice(rt, device_id=17, word_order="little", scales=scales)
    host, port = dev.start_tcp()
    try:
        link = make_link(
            {
                "kind": "modbus-tcp",
                "host": host,
                "port": port,
                "device_id": 17,
                "word_order": "little",
            }
        )
        link.open()
        samples = read_for(link, 0.8)
        raw = ModbusTcpClient(host, port=port)
        raw.connect()
        regs = raw.read_input_registers(mm.slot_address(0), count=8, device_id=17).registers
        raw.close()
        link.close()
    finally:
        dev.stop()
    assert_consecutive(samples)
    assert_equals_reference(samples, reference, scales)
    # independent decoding of the newest slot: low word first, accel in g
    accel_g = ModbusTcpClient.convert_from_registers(
        regs[4:6], ModbusTcpClient.DATATYPE.FLOAT32, word_order="little"
    )
    seq = ModbusTcpClient.convert_from_registers(
        regs[0:2], ModbusTcpClient.DATATYPE.UINT32, word_order="little"
    )
    assert accel_g == pytest.approx(reference.accel[seq] / 9.80665, rel=1e-6, abs=1e-6)


def test_wrong_word_order_or_device_id_is_refused_at_open():
    dev = ModbusDevice(realtime_rig(seed=2), device_id=3)
    host, port = dev.start_tcp()
    try:
        with pytest.raises(LinkError):
            make_link(
                {"kind": "modbus-tcp", "host": host, "port": port, "device_id": 4, "timeout_s": 0.5}
            ).open()
        with pytest.raises(LinkError, match="register map version"):
            make_link(
                {"kind": "modbus-tcp", "host": host, "port": port, "device_id": 3, "input_base": 2}
            ).open()
    finally:
        dev.stop()


def test_faults_injected_over_modbus_reach_the_running_rig():
    rt = realtime_rig(seed=2)
    with SimulatedDevice("modbus-tcp", rt) as dev:
        client = ModbusTcpClient(dev.link_config["host"], port=dev.link_config["port"])
        client.connect()
        try:
            head = mm.decode_header(
                client.read_input_registers(0, count=16, device_id=1).registers, "big"
            )
            assert not head.status & mm.STATUS_FAULT_INJECTED
            off = mm.FAULT_REGISTERS["bearing_supply"][0]
            rr = client.write_registers(off, mm.encode_f32(0.3, "big"), device_id=1)
            assert not rr.isError()
            assert rt.faults()["bearing_supply"] == pytest.approx(0.3, rel=1e-7)
            end = time.monotonic() + 5.0
            while rt.rig.bearing_supply == 1.0 and time.monotonic() < end:
                time.sleep(0.01)  # applied at the next tick
            assert math.isclose(rt.rig.bearing_supply, 0.3, rel_tol=1e-7)
            assert {k: v for k, v in rt.faults().items() if k != "bearing_supply"} == {
                k: v for k, v in mm.nominal_faults().items() if k != "bearing_supply"
            }
            back = mm.decode_faults(
                client.read_holding_registers(0, count=mm.FAULT_REGS, device_id=1).registers, "big"
            )
            assert back["bearing_supply"] == pytest.approx(0.3, rel=1e-7)
            head = mm.decode_header(
                client.read_input_registers(0, count=16, device_id=1).registers, "big"
            )
            assert head.status & mm.STATUS_FAULT_INJECTED
            off = mm.FAULT_REGISTERS["valve_gain"][0]
            rr = client.write_registers(off, mm.encode_f32(-1.0, "big"), device_id=1)
            assert rr.isError()  # refused, nothing applied
            assert rt.faults()["valve_gain"] == 1.0
        finally:
            client.close()


def test_a_killed_and_restarted_device_is_reconnected_and_the_seq_jump_shows():
    first = ModbusDevice(realtime_rig(seed=2))
    host, port = first.start_tcp()
    link = ReconnectingLink(
        lambda: ModbusLink.tcp(host, port, timeout_s=0.5), backoff_initial_s=0.05, backoff_max_s=0.4
    )
    link.open()
    before = read_for(link, 1.2)
    first.stop()
    down = read_for(link, 0.8)
    lost = link.events()
    assert [e["kind"] for e in lost] == ["link_lost"]
    assert lost[0]["t"] == before[-1].t
    second = ModbusDevice(realtime_rig(seed=5))
    second.start_tcp(host, port)
    try:
        after = []
        end = time.monotonic() + 10.0
        while len(after) < 50 and time.monotonic() < end:
            after += link.read(0.05)
    finally:
        second.stop()
        link.close()
    assert down == []
    assert [e["kind"] for e in link.events()] == ["link_restored"]
    assert_consecutive(before)
    assert_consecutive(after)
    assert after[0].seq < before[-1].seq  # the restarted device counts from 0 again
    assert link.counters()["disconnects"] == 1


@pytest.mark.parametrize("transport", ["modbus-tcp", "modbus-rtu"])
def test_repeated_device_restarts_are_each_one_lost_and_one_restored(transport, tmp_path):
    cycles = 4
    first = SimulatedDevice(transport, realtime_rig(seed=2), link_path=str(tmp_path / "rtu"))
    config = first.start()
    link = ReconnectingLink(
        lambda: make_link({**config, "timeout_s": 0.3}), backoff_initial_s=0.02, backoff_max_s=0.2
    )
    link.open()
    device = first
    for cycle in range(cycles):
        got = []
        end = time.monotonic() + 10.0
        while len(got) < 10 and time.monotonic() < end:
            got += link.read(0.05)
        assert len(got) >= 10, f"cycle {cycle}: no data after restart"
        device.stop()
        end = time.monotonic() + 10.0
        while link.connected and time.monotonic() < end:
            link.read(0.05)
        device = SimulatedDevice(
            transport,
            realtime_rig(seed=cycle),
            port=config.get("port", 0) if transport == "modbus-tcp" else 0,
            link_path=str(tmp_path / "rtu"),
        )
        device.start()
    while not link.connected and time.monotonic() < end:
        link.read(0.05)
    device.stop()
    link.close()
    kinds = [e["kind"] for e in link.events()]
    assert kinds == ["link_lost", "link_restored"] * cycles
    assert link.counters()["disconnects"] == cycles

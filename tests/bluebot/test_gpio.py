"""Fins and LEDs on gpiozero's mock pins: each fin's pin pair switches in opposite polarity
every half period of the frequency its gain maps to."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest

gpiozero_mock = pytest.importorskip("gpiozero.pins.mock")

from fishswarm.bluebot.gpio import GpioFins, GpioLeds  # noqa: E402
from fishswarm.bluebot.parameters import Wiring  # noqa: E402


@pytest.fixture
def factory() -> Iterator[object]:
    factory = gpiozero_mock.MockFactory()
    yield factory
    factory.reset()


def test_a_fins_pin_pair_switches_in_opposite_polarity_at_its_frequency(factory: object) -> None:
    fins = GpioFins(pin_factory=factory)
    caudal = [factory.pin(n) for n in Wiring().fin_pins[0]]  # type: ignore[attr-defined]
    try:
        for pin in caudal:
            pin.clear_states()
        # Gain 0.5 maps the caudal fin to 2 Hz (1–3 Hz over gains 0–1): a switch every 0.25 s.
        fins.set_gains(np.array([0.5, 0.0, 0.0, 0.0]))
        time.sleep(1.1)
        assert caudal[0].state != caudal[1].state
    finally:
        fins.close()
    first, second = caudal
    first.assert_states_and_times(
        [(0.0, False), (0.0, True), (0.25, False), (0.25, True), (0.25, False), (0.25, True)]
    )
    second.assert_states_and_times(
        [(0.0, False), (0.25, True), (0.25, False), (0.25, True), (0.25, False)]
    )
    # Closing switched both sides off.
    assert not first.state and not second.state


def test_gains_map_to_each_fins_frequency_and_zero_is_off(factory: object) -> None:
    fins = GpioFins(pin_factory=factory)
    try:
        fins.set_gains(np.array([0.5, 1.0, 0.0, 0.25]))
        # Caudal 1–3 Hz, dorsal 6 Hz, pectorals 1–10 Hz (SPEC §6).
        assert fins.frequencies == (2.0, 6.0, 0.0, 3.25)
        pectoral = [factory.pin(n) for n in Wiring().fin_pins[2]]  # type: ignore[attr-defined]
        time.sleep(0.2)
        assert [p.state for p in pectoral] == [False, False]
        with pytest.raises(ValueError, match="4 finite numbers"):
            fins.set_gains(np.array([0.5, np.nan, 0.0, 0.0]))
    finally:
        fins.close()


def test_stop_switches_every_fin_off_and_keeps_it_off(factory: object) -> None:
    fins = GpioFins(pin_factory=factory)
    pins = [factory.pin(n) for pair in Wiring().fin_pins for n in pair]  # type: ignore[attr-defined]
    try:
        fins.set_gains(np.ones(4))
        time.sleep(0.15)
        fins.stop()
        assert fins.frequencies == (0.0, 0.0, 0.0, 0.0)
        assert not any(pin.state for pin in pins)
        for pin in pins:
            pin.clear_states()
        time.sleep(0.3)
        assert all(len(pin.states) == 1 for pin in pins)  # no switch after the stop
    finally:
        fins.close()


def test_a_fins_new_rate_takes_over_from_its_next_half_period(factory: object) -> None:
    fins = GpioFins(pin_factory=factory)
    pin = factory.pin(Wiring().fin_pins[0][0])  # type: ignore[attr-defined]
    try:
        pin.clear_states()
        fins.set_gains(np.array([0.0 + 1e-9, 0.0, 0.0, 0.0]))  # the lowest gain: 1 Hz
        time.sleep(0.1)
        fins.set_gains(np.array([1.0, 0.0, 0.0, 0.0]))  # 3 Hz: a switch every 1/6 s
        time.sleep(0.45)
    finally:
        fins.close()
    pin.assert_states_and_times([(0.0, False), (0.0, True), (0.267, False), (0.167, True)])


def test_leds_follow_commands(factory: object) -> None:
    leds = GpioLeds(pin_factory=factory)
    pin = factory.pin(Wiring().led_pin)  # type: ignore[attr-defined]
    leds.set_lit(True)
    assert pin.state and leds.lit
    leds.set_lit(False)
    assert not pin.state and not leds.lit
    leds.set_lit(True)
    leds.close()
    assert not pin.state


def test_flashing_leds_switch_every_half_period_until_told_otherwise(factory: object) -> None:
    leds = GpioLeds(pin_factory=factory)
    pin = factory.pin(Wiring().led_pin)  # type: ignore[attr-defined]
    try:
        pin.clear_states()
        # 5 Hz: lit 0.1 s, dark 0.1 s (the driver flashes at 15 Hz; slower here so that the
        # test's timing tolerance holds on a busy machine).
        leds.set_flashing(5.0)
        assert leds.flash_frequency == 5.0
        time.sleep(0.45)
        leds.set_lit(True)
        assert leds.flash_frequency == 0.0 and pin.state
        states = len(pin.states)
        time.sleep(0.15)
        assert len(pin.states) == states  # steady: no more switches
        with pytest.raises(ValueError, match="positive number of Hz"):
            leds.set_flashing(0.0)
    finally:
        leds.close()
    assert not pin.state and leds.flash_frequency == 0.0
    # The pin's history (each state with the time since the one before): off when made,
    # on at once, then a switch every 0.1 s.
    flashed = pin.states[:6]
    assert [state.state for state in flashed] == [False, True, False, True, False, True]
    gaps = [state.timestamp for state in flashed[2:]]
    np.testing.assert_allclose(gaps, [0.1, 0.1, 0.1, 0.1], atol=0.04)


def test_leds_closed_while_flashing_are_dark_and_flash_no_more(factory: object) -> None:
    # The driver ends (Ctrl-C, an error) while its fish holds its place: the LEDs go dark
    # and say they flash at no frequency.
    leds = GpioLeds(pin_factory=factory)
    pin = factory.pin(Wiring().led_pin)  # type: ignore[attr-defined]
    leds.set_flashing(15.0)
    leds.close()
    assert not pin.state and leds.flash_frequency == 0.0


def test_a_fin_told_its_gains_again_and_again_keeps_its_beat(factory: object) -> None:
    """Gains every 0.1 s, more often than the 0.5-s half period of a 1-Hz fin: each repeat
    must not push the next switch away, or the fin would stall."""
    fins = GpioFins(pin_factory=factory)
    pin = factory.pin(Wiring().fin_pins[0][0])  # type: ignore[attr-defined]
    try:
        pin.clear_states()
        for _ in range(12):
            fins.set_gains(np.array([1e-9, 0.0, 0.0, 0.0]))  # the lowest gain: 1 Hz
            time.sleep(0.1)
    finally:
        fins.close()
    pin.assert_states_and_times(
        [(0.0, False), (0.0, True), (0.5, False), (0.5, True), (0.2, False)]
    )


def test_a_held_up_fin_resumes_its_rhythm_instead_of_catching_up(factory: object) -> None:
    """The fins' clock jumps 1 s ahead (the timing thread held up for six half periods of a
    3-Hz fin): the fin switches once and goes on every 1/6 s, not six times at once."""
    offset = [0.0]
    fins = GpioFins(pin_factory=factory, clock=lambda: time.monotonic() + offset[0])
    pin = factory.pin(Wiring().fin_pins[0][0])  # type: ignore[attr-defined]
    try:
        pin.clear_states()
        fins.set_gains(np.array([1.0, 0.0, 0.0, 0.0]))  # 3 Hz: a switch every 1/6 s
        time.sleep(0.1)
        offset[0] = 1.0
        time.sleep(0.3)
    finally:
        fins.close()
    pin.assert_states_and_times(
        [(0.0, False), (0.0, True), (0.167, False), (0.167, True), (0.067, False)]
    )


def test_the_two_sides_of_a_fins_h_bridge_are_never_on_together(factory: object) -> None:
    """Every pin change of every fin, in the order made: a side switches on only after the
    other side of its bridge is off (a short through the bridge otherwise)."""
    changes: list[tuple[str, bool]] = []

    class LoggedPin(gpiozero_mock.MockPin):  # type: ignore[misc,name-defined]
        def _change_state(self, value: bool) -> bool:
            changed = bool(super()._change_state(value))
            if changed:
                changes.append((self.info.name, value))
            return changed

    pairs = Wiring().fin_pins
    for pair in pairs:
        for n in pair:
            factory.pin(n, pin_class=LoggedPin)  # type: ignore[attr-defined]
    fins = GpioFins(pin_factory=factory)
    try:
        fins.set_gains(np.array([1.0, 1.0, 1.0, 1.0]))  # 3, 6, 10 and 10 Hz
        time.sleep(0.5)
        fins.set_gains(np.array([0.2, 0.5, 0.0, 0.7]))
        time.sleep(0.3)
    finally:
        fins.close()
    names = {n: factory.pin(n).info.name for pair in pairs for n in pair}  # type: ignore[attr-defined]
    high: set[str] = set()
    for name, value in changes:
        (high.add if value else high.discard)(name)
        for first, second in pairs:
            assert not {names[first], names[second]} <= high, f"both sides on: {name}"
    switched_on = sum(value for _, value in changes)
    assert switched_on >= 4 + 5 + 8 + 8  # every fin beat: 0.5 s at 3, 6, 10 and 10 Hz

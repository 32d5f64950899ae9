"""The BlueBot's GPIO outputs: fins beating at the frequency of their gains, and the LEDs.

A BlueBot's fin is an electromagnetic actuator on an H-bridge, driven without PWM: its pin
pair is switched to opposite polarities every half period 1/(2f), so the fin beats at f
(SPEC §6). One thread times all four fins (a Pi Zero has one core: one thread, not four);
gains become frequencies through :func:`fishswarm.bluebot.parameters.fin_frequencies`,
as in the simulator's effort. gpiozero (``robot`` extra) is imported when pins are opened;
tests pass gpiozero's ``MockFactory``.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import Wiring, fin_frequencies


def _output_device(pin: int, pin_factory: Any) -> Any:
    try:
        from gpiozero import DigitalOutputDevice
    except ImportError as error:
        raise ImportError(
            "the fins and LEDs need gpiozero: on Raspberry Pi OS apt install python3-gpiozero "
            "(deploy/ does), elsewhere pip install -e '.[robot]'"
        ) from error
    return DigitalOutputDevice(pin, initial_value=False, pin_factory=pin_factory)


class GpioFins:
    """The four fins on their H-bridge pin pairs. Implements the ``Fins`` port.

    Args:
        wiring: the robot's pins.
        pin_factory: gpiozero's pin factory (None: the Pi's own; tests: ``MockFactory()``).
        clock: monotonic time in s (the fin timing's clock).
    """

    def __init__(
        self,
        *,
        wiring: Wiring = Wiring(),
        pin_factory: Any = None,
        clock: Any = time.monotonic,
    ) -> None:
        self._clock = clock
        opened: list[Any] = []
        try:
            for first, second in wiring.fin_pins:
                opened.append(_output_device(first, pin_factory))
                opened.append(_output_device(second, pin_factory))
        except BaseException:
            for device in opened:
                device.close()
            raise
        self._pairs = [(opened[2 * n], opened[2 * n + 1]) for n in range(len(wiring.fin_pins))]
        count = len(self._pairs)
        self._frequency = [0.0] * count
        self._next_switch = [math.inf] * count
        self._polarity = [False] * count
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = False
        self._thread = threading.Thread(target=self._run, name="fishswarm-fins", daemon=True)
        self._thread.start()

    @property
    def frequencies(self) -> tuple[float, ...]:
        """The frequency each fin beats at now, Hz (0: off)."""
        with self._lock:
            return tuple(self._frequency)

    def set_gains(self, gains: NDArray[np.float64]) -> None:
        """Beat each fin at the frequency of its gain in [0, 1] (0: off); (4,).

        A fin already beating keeps its phase and switches at its new rate from its next
        half period on; a fin that was off starts at once.
        """
        values = np.asarray(gains, dtype=np.float64).reshape(1, -1)
        if values.shape[1] != len(self._pairs) or not np.isfinite(values).all():
            raise ValueError(f"fin gains must be {len(self._pairs)} finite numbers, got {gains!r}")
        frequency = fin_frequencies(values)[0].tolist()
        with self._lock:
            if self._closing:
                return
            now = self._clock()
            for fin, hz in enumerate(frequency):
                if hz <= 0.0:
                    self._switch_off(fin)
                elif self._frequency[fin] == 0.0:
                    self._next_switch[fin] = now
                else:
                    self._next_switch[fin] = min(self._next_switch[fin], now + 0.5 / hz)
                self._frequency[fin] = hz
        self._wake.set()

    def stop(self) -> None:
        """All fins off, at once."""
        with self._lock:
            for fin in range(len(self._pairs)):
                self._switch_off(fin)
        self._wake.set()

    def close(self) -> None:
        """Stop the fins, end the timing thread and release the pins."""
        with self._lock:
            self._closing = True
            for fin in range(len(self._pairs)):
                self._switch_off(fin)
        self._wake.set()
        self._thread.join(timeout=2.0)
        for first, second in self._pairs:
            first.close()
            second.close()

    def _switch_off(self, fin: int) -> None:
        first, second = self._pairs[fin]
        first.off()
        second.off()
        self._frequency[fin] = 0.0
        self._next_switch[fin] = math.inf

    def _run(self) -> None:
        while True:
            self._wake.clear()
            with self._lock:
                if self._closing:
                    return
                now = self._clock()
                for fin, due in enumerate(self._next_switch):
                    if due <= now:
                        self._switch(fin, now)
                wait = min(self._next_switch) - now
            self._wake.wait(timeout=None if math.isinf(wait) else max(wait, 0.0))

    def _switch(self, fin: int, now: float) -> None:
        """Reverse a fin's polarity and schedule its next switch."""
        polarity = not self._polarity[fin]
        self._polarity[fin] = polarity
        first, second = self._pairs[fin]
        # Break before make: never both sides of the H-bridge on at once.
        (second if polarity else first).off()
        (first if polarity else second).on()
        half = 0.5 / self._frequency[fin]
        following = self._next_switch[fin] + half
        # A thread held up by more than a half period resumes the rhythm from now.
        self._next_switch[fin] = following if following > now else now + half


class GpioLeds:
    """The three LEDs on one switch. Implements the ``Leds`` port.

    Args:
        wiring: the robot's pins.
        pin_factory: gpiozero's pin factory (None: the Pi's own).
    """

    def __init__(self, *, wiring: Wiring = Wiring(), pin_factory: Any = None) -> None:
        self._device = _output_device(wiring.led_pin, pin_factory)
        self._flash_frequency = 0.0

    @property
    def lit(self) -> bool:
        """Whether the LEDs are on now (a flashing LED is on half of the time)."""
        return bool(self._device.value)

    @property
    def flash_frequency(self) -> float:
        """The frequency the LEDs flash at, Hz (0: not flashing)."""
        return self._flash_frequency

    def set_lit(self, lit: bool) -> None:
        """Switch the LEDs on or off (a flashing stops)."""
        self._flash_frequency = 0.0
        if lit:
            self._device.on()
        else:
            self._device.off()

    def set_flashing(self, frequency: float) -> None:
        """Flash the LEDs at ``frequency`` Hz, lit for the first half of each period, by
        gpiozero's background thread (a Python thread: its rhythm does not wait for the
        event loop, but shares the interpreter, and a Pi Zero's one core, with the rest)."""
        if not (math.isfinite(frequency) and frequency > 0):
            raise ValueError(f"frequency must be a positive number of Hz, got {frequency}")
        half = 0.5 / frequency
        self._flash_frequency = float(frequency)
        self._device.blink(on_time=half, off_time=half, n=None, background=True)

    def close(self) -> None:
        """Switch the LEDs off and release the pin."""
        self._flash_frequency = 0.0
        self._device.off()
        self._device.close()

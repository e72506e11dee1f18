"""CAN frames of the amplifier stream, as described by ``creep_online/data/amplifier.dbc``.

``AMP_SAMPLE`` (0x100)  one sample per classic frame: Counter u16, U i24 (1e-5), Y i24 (1e-6)
``AMP_PAIR``   (0x101)  two samples per classic frame: Counter u16, Gen0/Gen1 u4, Y0/Y1 i20 (1e-5)
``AMP_INPUT``  (0x102)  input value of a generation: Gen u4, U i32 (1e-6)
``AMP_BLOCK``  (0x200)  seven samples per CAN FD frame: Counter u32, Status u32, (U_i, Y_i) i32 (1e-6)

Classic CAN carries at most ~8k frames/s at 1 Mbit/s, so 10 kHz needs
``AMP_PAIR`` (5k frames/s) or CAN FD ``AMP_BLOCK`` (1.43k frames/s). A pair
frame names the input *generation* (a 4-bit counter of input changes) instead
of carrying the input; the receiver pairs it with the last ``AMP_INPUT`` of
that generation and refuses (counts ``no_input``) samples whose generation it
has not seen, so a lost input frame never yields a wrong sample.

The encoders (used by the simulated plant) pack bits directly; the decoder
uses cantools on the DBC, so the two are independent implementations of the
same layout and the tests compare them.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from .frames import ParserStats, RawSample

ID_SAMPLE, ID_PAIR, ID_INPUT, ID_BLOCK = 0x100, 0x101, 0x102, 0x200
BLOCK_SAMPLES = 7
COUNTER_MODULUS = 1 << 16   # all counters are compared modulo 2**16
#: Largest DBC file read (a vehicle's whole network description is a few MB).
MAX_DBC_BYTES = 64 << 20


def dbc_path() -> Path:
    """The DBC file shipped with the package."""
    return Path(str(resources.files("creep_online") / "data" / "amplifier.dbc"))


# ------------------------------------------------------------------ encoders
def _field(value: int, start: int, bits: int) -> int:
    return (value & ((1 << bits) - 1)) << start


def _q(x: float, scale: float, bits: int) -> int:
    lim = 1 << (bits - 1)
    return min(max(round(x / scale), -lim), lim - 1)


def encode_sample(seq: int, u: float, y: float) -> tuple[int, bytes, bool]:
    v = _field(seq, 0, 16) | _field(_q(u, 1e-5, 24), 16, 24) | _field(_q(y, 1e-6, 24), 40, 24)
    return ID_SAMPLE, v.to_bytes(8, "little"), False


def encode_pair(seq: int, gen0: int, gen1: int, y0: float, y1: float) -> tuple[int, bytes, bool]:
    v = (_field(seq, 0, 16) | _field(gen0, 16, 4) | _field(gen1, 20, 4)
         | _field(_q(y0, 1e-5, 20), 24, 20) | _field(_q(y1, 1e-5, 20), 44, 20))
    return ID_PAIR, v.to_bytes(8, "little"), False


def encode_input(gen: int, u: float) -> tuple[int, bytes, bool]:
    v = _field(gen, 0, 4) | _field(_q(u, 1e-6, 32), 32, 32)
    return ID_INPUT, v.to_bytes(8, "little"), False


def encode_block(seq: int, status: int, us, ys) -> tuple[int, bytes, bool]:
    v = _field(seq, 0, 32) | _field(status, 32, 32)
    for i in range(BLOCK_SAMPLES):
        v |= _field(_q(us[i], 1e-6, 32), 64 + 64 * i, 32) | _field(_q(ys[i], 1e-6, 32), 96 + 64 * i, 32)
    return ID_BLOCK, v.to_bytes(64, "little"), True


# ------------------------------------------------------------------ decoder
class CanDecoder:
    """Turns amplifier CAN frames into raw samples (cantools does the bit work)."""

    def __init__(self, dbc: str | Path | None = None, stats: ParserStats | None = None) -> None:
        try:
            import cantools
        except ImportError:  # pragma: no cover - depends on the environment
            from ..errors import TransportError
            raise TransportError("CAN sources need cantools: pip install 'creep_online[can]'") from None
        from ..errors import DataError
        from .input_files import read_input
        path = Path(dbc) if dbc else dbc_path()
        text = read_input(path, what="DBC file", limit=MAX_DBC_BYTES, max_line=1 << 16)
        try:
            self.db = cantools.database.load_string(text.decode("utf-8", errors="replace"), database_format="dbc")
        except Exception as exc:  # noqa: BLE001 - any parse failure is a bad file
            raise DataError(f"{path}: not a usable DBC file ({str(exc).splitlines()[0][:100]})") from None
        self.stats = stats if stats is not None else ParserStats()
        self._msgs = {m.frame_id: m for m in self.db.messages}
        self._inputs: dict[int, float] = {}

    def decode(self, arbitration_id: int, data: bytes) -> list[RawSample]:
        st = self.stats
        msg = self._msgs.get(arbitration_id)
        if msg is None:
            st.other_frames += 1
            return []
        st.bytes += len(data)
        if len(data) != msg.length:
            st.malformed += 1
            return []
        try:
            sig = msg.decode(bytes(data), decode_choices=False, scaling=True)
        except Exception:  # noqa: BLE001 - cantools raises several types on bad payloads
            st.malformed += 1
            return []
        name = msg.name
        if name == "AMP_INPUT":
            g = int(sig["Gen"])
            self._inputs[g] = float(sig["U"])
            for k in range(1, 9):                 # generations "ahead" are stale now
                self._inputs.pop((g + k) % 16, None)
            st.frames += 1
            return []
        if name == "AMP_SAMPLE":
            st.frames += 1
            return [RawSample(int(sig["Counter"]), 0.0, float(sig["U"]), float(sig["Y"]), 0)]
        if name == "AMP_PAIR":
            st.frames += 1
            c = int(sig["Counter"])
            out = []
            for k, (gk, yk) in enumerate((("Gen0", "Y0"), ("Gen1", "Y1"))):
                u = self._inputs.get(int(sig[gk]))
                if u is None:
                    st.no_input += 1
                    continue
                out.append(RawSample((c + k) % COUNTER_MODULUS, 0.0, u, float(sig[yk]), 0))
            return out
        if name == "AMP_BLOCK":
            st.frames += 1
            c, status = int(sig["Counter"]), int(sig["Status"])
            return [RawSample((c + i) % COUNTER_MODULUS, 0.0, float(sig[f"U{i}"]), float(sig[f"Y{i}"]), status)
                    for i in range(BLOCK_SAMPLES)]
        st.other_frames += 1
        return []

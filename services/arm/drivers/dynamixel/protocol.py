"""DYNAMIXEL Protocol 2.0 framing, written independently of dynamixel-sdk so the emulator can check it.

Packet: ``FF FF FD 00 | ID | LEN_L LEN_H | INSTRUCTION | PARAMS... | CRC_L CRC_H`` where LEN counts the
instruction, the (byte-stuffed) parameters and the CRC. Byte stuffing inserts ``FD`` after any
``FF FF FD`` in the instruction + parameters. The CRC is CRC-16 with polynomial 0x8005 (the "CRC-16-IBM"
table of the ROBOTIS e-manual), initial value 0, no reflection, over everything before it.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = bytes([0xFF, 0xFF, 0xFD, 0x00])
BROADCAST_ID = 0xFE

PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08
STATUS, SYNC_READ, SYNC_WRITE, BULK_READ, BULK_WRITE = 0x55, 0x82, 0x83, 0x92, 0x93

# status packet error field (Protocol 2.0)
ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_CRC, ERR_DATA_RANGE, ERR_DATA_LENGTH, ERR_DATA_LIMIT, ERR_ACCESS = range(1, 8)
ERR_ALERT = 0x80  # hardware error: see the Hardware Error Status register


def _make_crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x8005) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return table


CRC_TABLE = _make_crc_table()


def crc16(data: bytes) -> int:
    crc = 0
    for b in data:
        crc = ((crc << 8) ^ CRC_TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(payload: bytes) -> bytes:
    """Insert 0xFD after every FF FF FD sequence."""
    out = bytearray()
    for b in payload:
        out.append(b)
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes) -> bytes:
    """Remove the 0xFD inserted after FF FF FD."""
    out = bytearray()
    i = 0
    while i < len(payload):
        out.append(payload[i])
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd" and i + 1 < len(payload) and payload[i + 1] == 0xFD:
            i += 1
        i += 1
    return bytes(out)


def build_packet(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete packet (header, stuffing, length, CRC)."""
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    pkt = HEADER + bytes([dxl_id, length & 0xFF, length >> 8]) + body
    crc = crc16(pkt)
    return pkt + bytes([crc & 0xFF, crc >> 8])


def build_status(dxl_id: int, error: int = 0, params: bytes = b"") -> bytes:
    return build_packet(dxl_id, STATUS, bytes([error]) + bytes(params))


@dataclass
class Packet:
    dxl_id: int
    instruction: int
    params: bytes
    crc_ok: bool


def parse_packets(buffer: bytearray) -> list[Packet]:
    """Consume every complete packet at the front of ``buffer`` (garbage before a header is dropped)."""
    out: list[Packet] = []
    while True:
        start = buffer.find(HEADER)
        if start < 0:
            # keep a possible partial header
            del buffer[: max(len(buffer) - 3, 0)]
            return out
        if start:
            del buffer[:start]
        if len(buffer) < 7:
            return out
        length = buffer[5] | (buffer[6] << 8)
        total = 7 + length
        if length < 3 or length > 4096:
            del buffer[:1]
            continue
        if len(buffer) < total:
            return out
        raw = bytes(buffer[:total])
        del buffer[:total]
        crc_ok = crc16(raw[:-2]) == (raw[-2] | (raw[-1] << 8))
        body = unstuff(raw[7:-2])
        out.append(Packet(raw[4], body[0], body[1:], crc_ok))

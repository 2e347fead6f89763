"""Receiver frames built by hand from the interface descriptions, independently of
``ins_gnss_ros.gnss.stream`` (which the tests check against them)."""


def ubx_frame(cls: int, msg_id: int, payload: bytes) -> bytes:
    """A UBX frame: sync, class, id, little-endian length, payload, 8-bit Fletcher checksum."""
    body = bytes([cls, msg_id]) + len(payload).to_bytes(2, "little") + payload
    ck_a = ck_b = 0
    for byte in body:
        ck_a = (ck_a + byte) % 256
        ck_b = (ck_b + ck_a) % 256
    return b"\xb5\x62" + body + bytes([ck_a, ck_b])


def nmea_sentence(sentence: str) -> bytes:
    """A complete NMEA 0183 sentence (``$``, fields, ``*`` XOR checksum, CR LF)."""
    value = 0
    for char in sentence.encode():
        value ^= char
    return f"${sentence}*{value:02X}\r\n".encode()

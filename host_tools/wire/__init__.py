"""Wire codecs: the CAN frames of the DBC (`dbc`), COBS/CRC and SLCAN byte framing
(`serial_framing`), and the unit a link writes (`items.WireItem`)."""

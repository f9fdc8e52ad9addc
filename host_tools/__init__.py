"""Host tools: DBC codec, CAN and serial links to the C estimator, host emulation loop."""

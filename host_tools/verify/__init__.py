"""Verification of the C estimator against the references: the host model of the node's
rules (`compare`), a bundle's integer and float references (`reference`), stream fault plans (`stream_faults`) and
model-upload faults (`upload_faults`)."""

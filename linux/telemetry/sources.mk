# SPDX-License-Identifier: MIT
# The telemetry transport's C files, one concern each (telem_internal.h has
# the map; telem.h is the API). Included by linux/telemetry/Makefile,
# linux/servod/Makefile and tests/fuzz/Makefile; tests/servod/
# test_servod_host.py reads the list.
TELEM_SOURCES := telem.c telem_push.c telem_wire.c telem_client.c telem_request.c telem_drain.c

#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Generate rpu_app's board configuration from the servo devicetree.

    gen_board_header.py --dts boards/<board>/servo.dts --board <board> \
        --out-dir build/rpu_app/<board> [--bindings rpu_app/dts/bindings]

Reads the devicetree with python-devicetree (edtlib) and the local YAML
bindings, starting at the node named by /chosen/servoamp,servo, and writes:

  board_config.h    every address, size, interrupt number, priority, period
                    and timer setting the firmware needs (BOARD_* macros)
  board_memory.ld   the linker MEMORY regions (carveout split into the
                    cacheable image part and the non-cacheable top part)
  board_config.mk   PLATFORM: the folder of rpu_app/platform/ for this CPU

What differs per SoC (the time base, the idle wake, the memory map for the
MMU or the MPU, the cooperative stop) comes from the platform's gen.py,
found by the servo CPU's compatible.

Both files are rewritten only when their content changes, so make does not
rebuild needlessly. Errors in the devicetree (missing nodes, a period the
16-bit TTC cannot produce, regions that are not section aligned...) stop the
build with a message naming the node.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_BINDINGS = HERE.parent / "dts" / "bindings"


GIC_SPI, GIC_PPI = 0, 1
GIC_IRQ_TYPE_EDGE_RISING, GIC_IRQ_TYPE_EDGE_FALLING = 1, 2
GIC_IRQ_TYPE_LEVEL_HIGH, GIC_IRQ_TYPE_LEVEL_LOW = 4, 8


PLATFORMS = HERE.parent / "platform"


class GenError(Exception):
    pass


def platform_for(cpu):
    """The platform whose gen.py names the servo CPU's compatible
    (rpu_app/platform/<soc>/gen.py: CPU_COMPATIBLE and the SoC's part of
    the generation)."""
    import importlib.util

    for gen in sorted(PLATFORMS.glob("*/gen.py")):
        spec = importlib.util.spec_from_file_location(f"platform_{gen.parent.name}", gen)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        if mod.CPU_COMPATIBLE in cpu.compats:
            mod.NAME = gen.parent.name
            return mod
    fail(cpu, f"no platform in {PLATFORMS} for CPU {cpu.compats}")


def fail(node, msg: str):
    where = node.path if node is not None else "devicetree"
    raise GenError(f"{where}: {msg}")


def prop(node, name: str):
    p = node.props.get(name)
    if p is None:
        fail(node, f"missing property '{name}'")
    return p.val


def one_reg(node, name: str | None = None):
    regs = node.regs
    if name is not None:
        for r in regs:
            if r.name == name:
                return r.addr, r.size
        fail(node, f"no reg named '{name}'")
    if not regs:
        fail(node, "no 'reg'")
    return regs[0].addr, regs[0].size


def gic_id(node, idx: int):
    """(GIC interrupt ID, 'level'|'edge') of the node's interrupt idx."""
    irqs = node.interrupts
    if idx >= len(irqs):
        fail(node, f"has {len(irqs)} interrupts, index {idx} requested")
    data = irqs[idx].data
    kind, num, flags = data["type"], data["irq"], data["flags"] & 0xF
    if kind == GIC_SPI:
        gid = 32 + num
    elif kind == GIC_PPI:
        gid = 16 + num
    else:
        fail(node, f"interrupt type {kind} is neither SPI nor PPI")
    if flags in (GIC_IRQ_TYPE_LEVEL_HIGH, GIC_IRQ_TYPE_LEVEL_LOW):
        trig = "level"
    elif flags in (GIC_IRQ_TYPE_EDGE_RISING, GIC_IRQ_TYPE_EDGE_FALLING):
        trig = "edge"
    else:
        fail(node, f"interrupt flags {flags:#x} unsupported")
    return gid, trig


def ttc_setting(node, freq: int, period_us: int):
    """Smallest prescaler giving a 16-bit interval for the period.

    TTC counters are 16 bits. Clock control: PS_EN=1 divides the input by
    2^(PS_V+1), PS_V 0..15. Returns (ps_en, ps_v, interval, ns_per_tick_q16,
    real_period_ns)."""
    choices = [(0, 0, 1)] + [(1, v, 1 << (v + 1)) for v in range(16)]
    for ps_en, ps_v, div in choices:
        ticks = (freq * period_us + div * 500000) // (div * 1000000)
        if 2 <= ticks <= 0x10000:
            ns_q16 = (div * 1_000_000_000 * 65536 + freq // 2) // freq
            real_ns = ticks * div * 1_000_000_000 // freq
            return ps_en, ps_v, ticks - 1, ns_q16, real_ns
    fail(node, f"cycle period {period_us} us not reachable with a 16-bit counter at {freq} Hz")


AMP_MAX_AXES = 8      # amp_lib/include/amp/amp_config.h
CO_MAX_NODES = 8      # rpu_app/src/canopen_master.h
BACKENDS = {"model": "AXIS_BACKEND_MODEL", "can": "AXIS_BACKEND_CAN"}


def opt(node, name: str, default):
    p = node.props.get(name)
    return default if p is None else p.val


CO_MASTER_NODE_ID = 127   # canopen_master.h: the master's time stamp PDO is 0x180 + this


def can_frame_bits(dlc: int) -> int:
    """Worst-case bits of a standard data frame (stuffing included)."""
    unstuffed = 34 + 8 * dlc          # SOF..CRC, the stuffed part
    return unstuffed + (unstuffed - 1) // 4 + 13


def fieldbus(servo, period_us: int, put, fail):
    """The axes (servoamp,servo-axis children) and the CAN controllers they
    use: BOARD_AXES(X), BOARD_CAN_BUSES(X) and the master's settings.
    Returns the CAN controller nodes used (their MMU sections)."""
    axes = [c for c in servo.children.values() if "servoamp,servo-axis" in c.compats]
    idx = []
    for a in axes:
        if not a.regs or a.regs[0].addr is None:
            fail(a, "needs reg = <axis index>")
        idx.append(a.regs[0].addr)
    axes = [a for _, a in sorted(zip(idx, axes), key=lambda t: t[0])]
    idx = sorted(idx)
    if idx != list(range(len(idx))):
        fail(servo, f"axes must be numbered 0..n-1 without gaps, got {idx}")
    if len(axes) > AMP_MAX_AXES:
        fail(servo, f"at most {AMP_MAX_AXES} axes")
    ctrls = opt(servo, "can-controllers", []) or []
    for c in ctrls:
        if "xlnx,zynq-can-1.0" not in c.compats:
            fail(c, "can-controllers must be xlnx,zynq-can-1.0 nodes")
    bitrate = opt(servo, "can-bitrate", 1_000_000)
    prio = opt(servo, "can-priority", 0x90)
    cycle_prio = prop(servo, "cycle-priority")
    if not 0 <= prio <= 0xF8 or prio % 8 or not prio < cycle_prio:
        fail(servo, "can-priority must be 0..0xf8, a multiple of 8, higher (numerically lower) than cycle-priority")
    rows, used_buses, nodes = [], set(), {}
    for i, a in enumerate(axes):
        be = prop(a, "servoamp,backend")
        bus = opt(a, "servoamp,can-bus", 0)
        node = opt(a, "servoamp,node-id", 0)
        if be == "can":
            if "servoamp,can-bus" not in a.props or "servoamp,node-id" not in a.props:
                fail(a, 'backend "can" needs servoamp,can-bus and servoamp,node-id')
            if not 0 <= bus < len(ctrls):
                fail(a, f"servoamp,can-bus {bus}: the servo node has {len(ctrls)} can-controllers")
            if not 1 <= node <= 127:
                fail(a, f"servoamp,node-id {node} must be 1..127")
            if node == CO_MASTER_NODE_ID and opt(servo, "can-time-stamp-ms", 1000):
                fail(a, f"servoamp,node-id {node} is the master's own (its time stamp PDO "
                        f"0x{0x180 + CO_MASTER_NODE_ID:03x}): use 1..126, or can-time-stamp-ms = <0>")
            if (bus, node) in nodes:
                fail(a, f"node id {node} on bus {bus} already used by {nodes[(bus, node)]}")
            nodes[(bus, node)] = a.path
            used_buses.add(bus)
        else:
            bus = node = 0
        rows.append((i, BACKENDS[be], bus, node))
    for b in used_buses:
        n = sum(1 for r in rows if r[1] == "AXIS_BACKEND_CAN" and r[2] == b)
        if n > CO_MAX_NODES:
            fail(servo, f"bus {b}: {n} CAN axes, at most {CO_MAX_NODES}")
        # SYNC + one RPDO and one TPDO of 6 bytes per axis, plus each
        # drive's heartbeat (1 byte): all of them may fall in one cycle;
        # worst-case stuffing (bench/fieldbus measured the busiest cycles
        # above the estimate without the heartbeats)
        bits = can_frame_bits(0) + n * (2 * can_frame_bits(6) + can_frame_bits(1))
        if opt(servo, "can-time-stamp-ms", 1000):
            bits += can_frame_bits(4)     # the master's time stamp, in its cycles
        budget = bitrate * period_us // 1_000_000
        if bits > budget:
            fail(servo, f"bus {b}: {n} axes need up to {bits} bit times per cycle, "
                        f"{budget} available at {bitrate} bit/s and {period_us} us")
        put(f"BOARD_CAN{b}_LOAD_PERMILLE", bits * 1000 // budget,
            f"worst-case bus load per cycle, {n} axes")
    put("BOARD_AXIS_COUNT", len(rows), "axes described (the others: internal model)")
    put("BOARD_CAN_AXES", sum(1 for r in rows if r[1] == "AXIS_BACKEND_CAN"))
    put("BOARD_CAN_COUNT", len(ctrls), "CAN controllers the firmware may use")
    put("BOARD_CAN_USED_MASK", sum(1 << b for b in used_buses), "buses with at least one axis")
    ref = None
    bus_rows = []
    for b, c in enumerate(ctrls):
        base = one_reg(c)[0]
        irq, trig = gic_id(c, 0)
        if irq < 32:
            fail(c, "the CAN interrupt must be an SPI")
        hz = prop(c, "clock-frequency")
        if ref is not None and hz != ref:
            fail(c, "every CAN controller must have the same clock-frequency")
        ref = hz
        bus_rows.append((b, base, irq, 1 if trig == "level" else 0))
        put(f"BOARD_CAN{b}_BASE", base, c.path)
        put(f"BOARD_CAN{b}_IRQ", irq, f"GIC ID, {trig}-triggered")
    if ctrls:
        if ref % bitrate or not 8 <= ref // bitrate <= 256 * 25:
            fail(servo, f"can-bitrate {bitrate} not reachable from {ref} Hz")
        put("BOARD_CAN_REF_HZ", ref)
    else:
        put("BOARD_CAN_REF_HZ", 0, "no CAN controller")
    put("BOARD_CAN_BITRATE", bitrate)
    put("BOARD_CAN_PRIORITY", prio)
    for name, dflt, lo, hi in (("can-heartbeat-producer-ms", 20, 1, 65535),
                               ("can-heartbeat-consumer-ms", 60, 1, 65535),
                               ("can-sdo-timeout-ms", 50, 1, 65535),
                               ("can-boot-timeout-ms", 500, 1, 65535),
                               ("can-time-stamp-ms", 1000, 0, 65535)):
        v = opt(servo, name, dflt)
        if not lo <= v <= hi:
            fail(servo, f"{name} must be {lo}..{hi}")
        put("BOARD_" + name.upper().replace("-", "_"), v)
    if opt(servo, "can-heartbeat-consumer-ms", 60) <= opt(servo, "can-heartbeat-producer-ms", 20):
        fail(servo, "can-heartbeat-consumer-ms must be longer than can-heartbeat-producer-ms")
    macros = {
        "BOARD_AXES": ("X(index, backend, can bus, node id)", [f"X({i}, {be}, {b}, {n})" for i, be, b, n in rows]),
        "BOARD_CAN_BUSES": ("X(index, base, GIC ID, level)",
                            [f"X({b}, 0x{base:08x}u, {irq}u, {lvl})" for b, base, irq, lvl in bus_rows]),
    }
    put("__X_MACROS__", macros)
    return [ctrls[b] for b in sorted(used_buses)]


def build(dts: Path, bindings: list[Path], board: str):
    try:
        from devicetree import edtlib
    except ImportError as e:  # pragma: no cover - environment problem
        raise GenError("python-devicetree is not installed (scripts/bootstrap.sh)") from e

    edt = edtlib.EDT(str(dts), [str(b) for b in bindings], werror=True)
    servo = edt.chosen_node("servoamp,servo")
    if servo is None:
        raise GenError(f"{dts}: /chosen has no 'servoamp,servo'")

    cfg: dict[str, object] = {}
    comments: dict[str, str] = {}

    def put(name, value, comment=""):
        cfg[name] = value
        if comment:
            comments[name] = comment

    cpu = prop(servo, "cpu")
    put("BOARD_CPU_ID", cpu.regs[0].addr if cpu.regs else 0, f"{cpu.path}")

    # ---- the platform (rpu_app/platform/<soc>/gen.py), by the CPU -------
    plat = platform_for(cpu)
    put("BOARD_CPU_HAS_VBAR", 1 if plat.HAS_VBAR else 0, f"platform {plat.NAME}")
    put("BOARD_GIC_OWNED", 1 if plat.GIC_OWNED else 0,
        "this core's own GIC (enabled here), not one shared with Linux")
    put("BOARD_GIC_IDS", plat.GIC_IDS, "interrupt IDs of this core's GIC (the IRQ descriptor table)")

    # ---- memory ------------------------------------------------------
    carve = prop(servo, "memory-region")
    c_base, c_size = one_reg(carve)
    unc = prop(servo, "uncached-size")
    plat.check_carveout(carve, servo, c_base, c_size, unc, fail)
    trace = prop(servo, "trace-size")
    if not 256 <= trace <= unc or trace % 32:
        fail(servo, "trace-size must be 256..uncached-size bytes, multiple of 32")
    put("BOARD_CARVEOUT_BASE", c_base, carve.path)
    put("BOARD_CARVEOUT_SIZE", c_size)
    put("BOARD_IMAGE_BASE", c_base, "cacheable part: code, data, stacks")
    put("BOARD_IMAGE_SIZE", c_size - unc)
    put("BOARD_UNCACHED_BASE", c_base + c_size - unc, "non-cacheable part: trace buffer")
    put("BOARD_UNCACHED_SIZE", unc)
    put("BOARD_TRACE_SIZE", trace)

    # ---- OCM contract ------------------------------------------------
    amp = prop(servo, "amp-region")
    a_base, a_size = one_reg(amp)
    put("BOARD_AMP_BASE", a_base, amp.path)
    put("BOARD_AMP_SIZE", a_size)
    ocm = amp.parent
    o_base, o_size = one_reg(ocm)
    put("BOARD_OCM_BASE", o_base, ocm.path)
    put("BOARD_OCM_SIZE", o_size)
    contract = [amp]
    # The cooperative stop (servoamp's Zynq-7000 driver): control and status
    # words, the park loop, the boot register. A platform whose remoteproc
    # driver powers the core down (the R5's upstream one) has none.
    if plat.STOP_CONTRACT:
        ctl = prop(servo, "stop-control")
        put("BOARD_STOP_CONTROL_ADDR", one_reg(ctl, "control")[0], ctl.path)
        put("BOARD_STOP_STATUS_ADDR", one_reg(ctl, "status")[0])
        park = prop(servo, "cpu-park")
        put("BOARD_PARK_ADDR", one_reg(park)[0], park.path)
        boot = prop(servo, "boot-register")
        put("BOARD_BOOT_REG_ADDR", one_reg(boot)[0], boot.path)
        contract += [ctl, park, boot]
    else:
        for name in ("stop-control", "cpu-park", "boot-register"):
            if name in servo.props:
                fail(servo, f"'{name}': platform {plat.NAME} has no cooperative stop")
    put("BOARD_HAS_STOP_CONTRACT", 1 if plat.STOP_CONTRACT else 0)
    for n in contract:
        if n.parent is not ocm:
            fail(n, "must be a child of the OCM node")

    # ---- interrupt controller and timers ------------------------------
    ttc = prop(servo, "cycle-timer")
    gic = ttc.interrupts[0].controller if ttc.interrupts else None
    if gic is None or not set(gic.compats) & {"arm,cortex-a9-gic", "arm,pl390"}:
        fail(ttc, "interrupt parent must be an arm,cortex-a9-gic or arm,pl390 (GICv1)")
    put("BOARD_GICD_BASE", one_reg(gic, "distributor")[0], gic.path)
    put("BOARD_GICC_BASE", one_reg(gic, "cpu")[0])

    # the time base and the idle wake: the platform's
    plat_devs = plat.timers(edt, cpu, servo, put, fail, prop, one_reg, gic_id)

    idx = prop(servo, "cycle-counter")
    if not 0 <= idx <= 2:
        fail(servo, "cycle-counter must be 0..2")
    period = prop(servo, "cycle-period-us")
    if not 10 <= period <= 1_000_000:
        fail(servo, "cycle-period-us must be 10..1000000")
    ttc_hz = prop(ttc, "clock-frequency")
    irq, trig = gic_id(ttc, idx)
    if irq < 32:
        fail(ttc, "the cycle interrupt must be an SPI")
    ps_en, ps_v, interval, ns_q16, real_ns = ttc_setting(servo, ttc_hz, period)
    put("BOARD_TTC_BASE", one_reg(ttc)[0], ttc.path)
    put("BOARD_TTC_HZ", ttc_hz)
    put("BOARD_CYCLE_COUNTER", idx)
    put("BOARD_CYCLE_IRQ", irq, f"GIC ID, {trig}-triggered")
    put("BOARD_CYCLE_IRQ_LEVEL", 1 if trig == "level" else 0)
    put("BOARD_CYCLE_PERIOD_US", period)
    put("BOARD_CYCLE_PERIOD_NS", real_ns, "what the counter really produces")
    put("BOARD_CYCLE_PS_EN", ps_en)
    put("BOARD_CYCLE_PS_V", ps_v, "prescaler: divide by 2^(PS_V+1) when PS_EN")
    put("BOARD_CYCLE_INTERVAL", interval, "interval register (period - 1 ticks)")
    put("BOARD_CYCLE_NS_PER_TICK_Q16", ns_q16, "counter tick in ns, Q16.16")
    lidx = prop(servo, "linux-cycle-counter")
    if not 0 <= lidx <= 2 or lidx == idx:
        fail(servo, "linux-cycle-counter must be 0..2 and differ from cycle-counter")
    lirq, _ = gic_id(ttc, lidx)
    put("BOARD_LINUX_CYCLE_COUNTER", lidx, "Linux's counter (programmed here, cleared by Linux)")
    put("BOARD_LINUX_CYCLE_IRQ", lirq, "GIC ID of Linux's cycle interrupt (never touched here)")
    prio = prop(servo, "cycle-priority")
    nprio = prop(servo, "nest-test-priority")
    sgi = prop(servo, "nest-test-sgi")
    for name, v in (("cycle-priority", prio), ("nest-test-priority", nprio)):
        if not 0 <= v <= 0xF8 or v % 8:
            fail(servo, f"{name} must be 0..0xf8, multiple of 8 (A9: 32 levels)")
    if not nprio < prio:
        fail(servo, "nest-test-priority must be higher (numerically lower) than cycle-priority")
    if not 8 <= sgi <= 15:
        fail(servo, "nest-test-sgi must be 8..15 (0..7 are Linux IPIs)")
    put("BOARD_CYCLE_PRIORITY", prio)
    put("BOARD_NEST_TEST_SGI", sgi)
    put("BOARD_NEST_TEST_PRIORITY", nprio)

    uart = prop(servo, "console")
    put("BOARD_UART_BASE", one_reg(uart)[0], uart.path)
    put("BOARD_UART_REF_HZ", prop(uart, "clock-frequency"))
    put("BOARD_UART_BAUD", prop(uart, "current-speed"))

    # the Zynq-7000's SLCR: the console UART's clock gate is checked there
    slcr = edt.compat2okay.get("xlnx,zynq-slcr", [])
    if plat.SLCR and not slcr:
        raise GenError(f"{dts}: no xlnx,zynq-slcr node")
    put("BOARD_HAS_SLCR", 1 if slcr else 0)
    if slcr:
        put("BOARD_SLCR_BASE", one_reg(slcr[0])[0], slcr[0].path)

    can_devs = fieldbus(servo, period, put, fail)

    put("BOARD_ATTACH_RETRY_CYCLES", prop(servo, "attach-retry-cycles"))
    put("BOARD_STATS_CYCLES", prop(servo, "stats-cycles"))

    # ---- memory protection: what the firmware uses, nothing else ------
    for name, v in cfg.items():
        if name.endswith("_IRQ") and isinstance(v, int) and not v < plat.GIC_IDS:
            fail(servo, f"{name} = {v}: beyond the {plat.GIC_IDS} interrupt IDs of platform {plat.NAME}'s GIC")
    devices = [uart, ttc, gic, *slcr[:1], *plat_devs, *can_devs]
    mmu = plat.memory_map(cfg, carve, ocm, devices, fail)
    put("__PLATFORM__", plat.NAME)

    return cfg, comments, mmu


def render_header(cfg, comments, mmu, board: str, dts: Path) -> str:
    out = [
        "/* Generated by rpu_app/scripts/gen_board_header.py: do not edit. */",
        f"/* Board: {board}, devicetree: {dts.as_posix()} */",
        "#ifndef BOARD_CONFIG_H",
        "#define BOARD_CONFIG_H",
        "",
        "/* Unsigned in C, plain numbers in assembly (like Linux's _AC). */",
        "#ifdef __ASSEMBLER__",
        "#define BOARD_U(x) x",
        "#else",
        "#define BOARD_U(x) x##u",
        "#endif",
        "",
        f'#define BOARD_NAME "{board}"',
    ]
    xmacros = cfg.get("__X_MACROS__", {})
    for k, v in cfg.items():
        if k in ("__X_MACROS__", "__PLATFORM__", "__MEMPROT_MACRO__", "__LD_EXTRA__"):
            continue
        val = f"BOARD_U(0x{v:08x})" if k.endswith(("_BASE", "_ADDR", "_SIZE", "_Q16")) else f"BOARD_U({v})"
        c = comments.get(k)
        out.append(f"#define {k} {val}" + (f"\t/* {c} */" if c else ""))
    for name, (what, rows) in xmacros.items():
        out += ["", f"/* {what} */", f"#define {name}(X) \\"]
        out += [f"\t{r} \\" for r in rows]
        out.append("")
    macro, what_regions = cfg["__MEMPROT_MACRO__"]  # type: ignore[misc]
    out += ["", "#ifndef __ASSEMBLER__",
            f"/* {what_regions}: X(base, size, attributes). */",
            f"#define {macro}(X) \\"]
    for base, size, attr, what in mmu:
        out.append(f"\tX(0x{base:08x}u, 0x{size:08x}u, {attr}) /* {what} */ \\")
    out += ["", "#endif /* __ASSEMBLER__ */", "", "#endif /* BOARD_CONFIG_H */", ""]
    return "\n".join(out)


def render_ld(cfg, board: str) -> str:
    return "\n".join([
        "/* Generated by rpu_app/scripts/gen_board_header.py: do not edit. */",
        f"/* Board: {board} */",
        "MEMORY",
        "{",
        f"\tIMAGE (rwx) : ORIGIN = 0x{cfg['BOARD_IMAGE_BASE']:08x}, LENGTH = 0x{cfg['BOARD_IMAGE_SIZE']:08x}",
        f"\tUNCACHED (rw) : ORIGIN = 0x{cfg['BOARD_UNCACHED_BASE']:08x}, LENGTH = 0x{cfg['BOARD_UNCACHED_SIZE']:08x}",
        f"\tOCM (rwx) : ORIGIN = 0x{cfg['BOARD_OCM_BASE']:08x}, LENGTH = 0x{cfg['BOARD_OCM_SIZE']:08x}",
        "}",
        f"__carveout_start = 0x{cfg['BOARD_CARVEOUT_BASE']:08x};",
        f"__carveout_end = 0x{cfg['BOARD_CARVEOUT_BASE'] + cfg['BOARD_CARVEOUT_SIZE']:08x};",
        f"__trace_size = 0x{cfg['BOARD_TRACE_SIZE']:x};",
        *cfg.get("__LD_EXTRA__", []),  # type: ignore[misc]
        "",
    ])


def render_mk(cfg, board: str) -> str:
    return "\n".join([
        "# Generated by rpu_app/scripts/gen_board_header.py: do not edit.",
        f"# Board: {board}",
        f"PLATFORM := {cfg['__PLATFORM__']}",
        "",
    ])


def write_if_changed(path: Path, text: str) -> None:
    if path.exists() and path.read_text() == text:
        return
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dts", required=True, type=Path)
    ap.add_argument("--board", required=True)
    ap.add_argument("--out-dir", required=True, type=Path)
    ap.add_argument("--bindings", action="append", type=Path,
                    help=f"binding directory (default {DEFAULT_BINDINGS})")
    a = ap.parse_args(argv)
    try:
        cfg, comments, mmu = build(a.dts, a.bindings or [DEFAULT_BINDINGS], a.board)
    except GenError as e:
        print(f"gen_board_header: error: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # edtlib errors carry their own message
        print(f"gen_board_header: error: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    a.out_dir.mkdir(parents=True, exist_ok=True)
    write_if_changed(a.out_dir / "board_config.h", render_header(cfg, comments, mmu, a.board, a.dts))
    write_if_changed(a.out_dir / "board_memory.ld", render_ld(cfg, a.board))
    write_if_changed(a.out_dir / "board_config.mk", render_mk(cfg, a.board))
    return 0


if __name__ == "__main__":
    sys.exit(main())

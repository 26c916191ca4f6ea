#!/bin/busybox sh
# servoamp guest /init (PID 1): mount the pseudo file systems, load the
# servo core's remoteproc driver, and keep a shell on the console (ttyPS0).
/bin/busybox mount -t proc proc /proc
/bin/busybox --install -s
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
mkdir -p /dev/pts /var/lib/servod
mount -t devpts devpts /dev/pts
mount -t debugfs debugfs /sys/kernel/debug
mount -t tmpfs tmpfs /tmp
mount -t tmpfs tmpfs /run
hostname servoamp
ip link set lo up 2>/dev/null

for m in /lib/modules/*.ko; do
	[ -f "$m" ] || continue
	insmod "$m" || echo "servoamp: insmod $m failed"
done

# PREEMPT_RT (SERVOAMP_KERNEL=rt): every interrupt handler runs in a thread
# irq/NN-NAME at SCHED_FIFO 50. The cycle interrupt's thread (its UIO
# driver's own, linux/uio/servoamp_cycle_uio.c) is the first half of
# servod's wake-up (it wakes servod's read() on /dev/uioN): FIFO 81, above
# servod's cycle thread (80) and every other interrupt thread (50:
# Ethernet, UART), so neither the network nor the console delays the cycle
# (docs/cycle-rt.md). Linux runs on CPU0 only
# (maxcpus=1). On the vanilla kernel that thread exists but never runs (the
# hard interrupt wakes servod): its priority does not matter there.
# Only where the cycle interrupt's driver bound a device (a board whose
# devicetree has no cycle interrupt node gets the message below).
if ls -d /sys/bus/platform/drivers/servoamp-cycle-uio/*/uio >/dev/null 2>&1; then
	irqprio cycle-interrupt 81 || echo "servoamp: irqprio cycle-interrupt failed"
elif [ -e /lib/modules/servoamp_cycle_uio.ko ]; then
	echo "servoamp: no cycle interrupt in the devicetree (servoamp_cycle_uio bound no device)"
fi

# PREEMPT_RT prints kernel messages to the console from a kthread, after
# the fact: a line such as remoteproc's "crash detected" then lands in the
# middle of a shell command's output line (the default kernel prints in
# the caller's context, before the shell answers). Keep only emergencies
# and alerts (soft lockups, workqueue lockups: the stall detectors) on the
# console there; everything stays in dmesg.
# (/sys/kernel/realtime comes with the RT patch series of the Zynq-7000's
# 6.1; mainline PREEMPT_RT, the ZynqMP's 6.12, says it in uname -v.)
if [ "$(cat /sys/kernel/realtime 2>/dev/null)" = 1 ] || uname -v | grep -q PREEMPT_RT; then
	dmesg -n 3
	echo "servoamp: PREEMPT_RT: console loglevel 3 (dmesg has every message)"
fi

cat >/etc/profile <<'EOF'
export PATH=/bin:/sbin:/usr/bin:/usr/sbin
export PS1='servoamp:\w# '
# A serial console reports no size; without one, the shell wraps at 80.
case "$(stty size 2>/dev/null)" in ""|"0 0") stty rows 50 cols 250 ;; esac
EOF

echo "servoamp: userspace ready at $(cut -d' ' -f1 /proc/uptime) s"
echo "servoamp: firmware: $(ls /lib/firmware 2>/dev/null | tr '\n' ' ')"

# PID 1 must never exit: respawn the console shell.
while :; do
	setsid cttyhack sh -l
	echo "servoamp: shell exited, restarting"
done

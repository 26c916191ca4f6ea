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

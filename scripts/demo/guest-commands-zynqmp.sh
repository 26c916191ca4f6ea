# Guest shell commands of the emulated controller demo on the ZynqMP
# (scripts/demo.sh --board zynqmp_qemu; board.yaml demo.guest_commands),
# one command a line, run on the Linux console of the A53: rpu_app on R5 0
# through Linux's upstream xlnx_r5_remoteproc. Not yet here, unlike the
# Zynq-7000's script: the hang and its recovery (servod's restart through
# the upstream driver, issue 35 item 3; docs/boot-flow-zynqmp.md).
uname -a
cat /sys/class/remoteproc/remoteproc0/name /sys/class/remoteproc/remoteproc0/state
ls -l /lib/firmware
# 1. servod: the cycle daemon (SCHED_FIFO thread on the cycle interrupt, through UIO);
#    the R5's time base is its 1 GHz cycle counter (board.yaml servo.clock_hz)
(servod --id zynqmp_qemu --servo-clock-hz 1000000000 > /tmp/servod.log 2>&1 &)
while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done
# 2. load and start the servo firmware on R5 0 through the remoteproc sysfs
echo rpu_app.elf > /sys/class/remoteproc/remoteproc0/firmware
echo start > /sys/class/remoteproc/remoteproc0/state
cat /sys/class/remoteproc/remoteproc0/state
while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done
head -n 8 /sys/kernel/debug/remoteproc/remoteproc0/trace0
# 3. the cycle runs: both sides' counts, parameters
sleep 2
ampctl status
ampctl stats
ampctl param list
ampctl param set pos_kp 80
ampctl param get pos_kp
# 4. an operator's stop: the upstream driver powers R5 0 down; servod restarts nothing
echo stop > /sys/class/remoteproc/remoteproc0/state
sleep 2
cat /sys/class/remoteproc/remoteproc0/state
tail -n 3 /tmp/servod.log
ampctl param get pos_kp; echo "ampctl exit status $? (3 = servo not running)"

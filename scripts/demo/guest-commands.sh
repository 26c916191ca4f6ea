# Guest shell commands of the emulated controller demo (scripts/demo.sh),
# one command a line, run on the Linux console of the emulated board
# (either: the Zynq-7000's servo core is A9 CPU1 under servoamp's driver,
# the ZynqMP's R5 0 under Linux's upstream xlnx_r5_remoteproc). demo.sh
# sets SERVOD_ARGS first: servod's options that name the board
# (python -m servoamp.netboard --servod-args BOARD: its id and the rate of
# the servo core's time base, board.yaml servo.clock_hz).
uname -a
# the servo core's remoteproc: the one the OCM mailbox's devicetree node names
RPROC=$(servod --find-rproc); echo $RPROC
cat $RPROC/name $RPROC/state
ls -l /lib/firmware
# 1. servod: the cycle daemon (SCHED_FIFO thread on the cycle interrupt, through UIO)
(servod $SERVOD_ARGS > /tmp/servod.log 2>&1 &)
while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done
# 2. load and start the servo firmware through the remoteproc sysfs
echo rpu_app.elf > $RPROC/firmware
echo start > $RPROC/state
cat $RPROC/state
while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done
head -n 8 /sys/kernel/debug/remoteproc/${RPROC##*/}/trace0
# 3. the cycle runs: both sides' counts, parameters
sleep 2
ampctl status
ampctl stats
ampctl param list
ampctl param set pos_kp 80
ampctl param get pos_kp
# 4. fault and recovery: hang the firmware; servod detects it and restarts it through remoteproc
#    (a crash report first where the driver has report_crash), parameters come back
ampctl debug hang
sleep 2
tail -n 6 /tmp/servod.log
ampctl status
ampctl param get pos_kp
# 5. an operator's stop is final: servod restarts nothing and waits for a start (the A9's firmware
#    says STOPPING and parks; the upstream driver powers R5 0 down)
echo stop > $RPROC/state
sleep 2
cat $RPROC/state
tail -n 3 /tmp/servod.log
ampctl param get pos_kp; echo "ampctl exit status $? (3 = servo not running)"

# Guest shell commands of the emulated controller demo (scripts/demo.sh),
# one command a line, run on the Linux console of the emulated Zynq-7000.
uname -a
cat /sys/class/remoteproc/remoteproc0/name /sys/class/remoteproc/remoteproc0/state
ls -l /lib/firmware
echo rpu_app.elf > /sys/class/remoteproc/remoteproc0/firmware
echo start > /sys/class/remoteproc/remoteproc0/state
cat /sys/class/remoteproc/remoteproc0/state
sleep 1
cat /sys/kernel/debug/remoteproc/remoteproc0/trace0
sleep 1
tail -n 3 /sys/kernel/debug/remoteproc/remoteproc0/trace0
echo stop > /sys/class/remoteproc/remoteproc0/state
cat /sys/class/remoteproc/remoteproc0/state
dmesg | grep -i -E 'remoteproc|zynq-servo' | tail -n 8

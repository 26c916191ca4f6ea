#!/bin/busybox sh
# servoamp-net [ADDR/PREFIX [GATEWAY]]: bring up the board's Ethernet (gem0,
# eth0) for QEMU user networking (-nic user,model=cadence_gem,...): guest
# 10.0.2.15/24, gateway 10.0.2.2 by default. Idempotent. Waits up to 5 s
# for the PHY's link. Exit 1 when there is no eth0.
dev=${SERVOAMP_NET_DEV:-eth0}
addr=${1:-10.0.2.15/24}
gw=${2:-10.0.2.2}
if [ ! -e "/sys/class/net/$dev" ]; then
	echo "servoamp-net: no $dev"
	exit 1
fi
ip link set "$dev" up || exit 1
ip -4 addr show dev "$dev" | grep -q "inet ${addr%/*}/" || ip addr add "$addr" dev "$dev" || exit 1
ip route show | grep -q '^default' || ip route add default via "$gw" dev "$dev" 2>/dev/null
i=0
while [ "$(cat "/sys/class/net/$dev/carrier" 2>/dev/null)" != 1 ] && [ $i -lt 100 ]; do
	sleep 0.05
	i=$((i + 1))
done
echo "servoamp-net: $dev $addr gateway $gw carrier $(cat "/sys/class/net/$dev/carrier" 2>/dev/null)"

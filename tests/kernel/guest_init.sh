#!/bin/sh
# /init of the kernel-level test's initramfs (busybox sh): loads i2c-dev and i2c-stub with the
# suit's chips and vfb (a framebuffer in memory), finds the stub's /dev/i2c-N and vfb's /dev/fbN,
# runs the guest program on them, prints the result marker and powers off (qemu runs with
# -no-reboot, so that ends the run).
export PATH=/bin

finish() {
    echo "CAPHUB-KERNEL-TEST: $1"
    sync
    poweroff -f
    sleep 10  # poweroff -f returns before the machine is off
}

fail() {
    echo "init: $*"
    finish FAIL
}

mount -t proc proc /proc || fail "cannot mount /proc"
mount -t sysfs sysfs /sys || fail "cannot mount /sys"
mount -t devtmpfs devtmpfs /dev || fail "cannot mount /dev"

echo  # after the firmware's last line, which has no newline
echo "kernel: $(uname -r) ($(uname -m))"

# i2c-stub emulates one chip per address: 0x68 ICM-20948, 0x6a LSM6DSOX, 0x1c LIS3MDL,
# 0x70 TCA9548A. The ICM-20948 (index 0) selects its register bank with bits 5:4 of 0x7F;
# registers 0x00-0x7E are banked (banks 1-3 kept apart from bank 0).
stubParams="chip_addr=0x68,0x6a,0x1c,0x70 bank_reg=0x7f bank_mask=0x30 bank_start=0x00"
stubParams="$stubParams bank_end=0x7e"
# vfb registers nothing without vfb_enable=1. It starts at 640x480, 8 bpp; its default 1 MiB of
# memory is too small for 32 bpp at that size (1,228,800 bytes), so it gets 2 MiB.
vfbParams="vfb_enable=1 videomemorysize=2097152"
while read -r module; do
    case "$module" in
    */i2c-stub.ko) params=$stubParams ;;
    */vfb.ko) params=$vfbParams ;;
    *) params= ;;
    esac
    # shellcheck disable=SC2086  # params is a list of words
    insmod "$module" $params || fail "insmod $module $params failed"
    echo "init: loaded ${module##*/} $params"
done </etc/modules

device=
for _ in 1 2 3 4 5 6 7 8 9 10; do  # up to 1 s for udev-less devtmpfs to show the node
    for dir in /sys/class/i2c-dev/i2c-*; do
        [ -r "$dir/name" ] || continue
        if [ "$(cat "$dir/name")" = "SMBus stub driver" ] && [ -c "/dev/${dir##*/}" ]; then
            device=/dev/${dir##*/}
        fi
    done
    [ -n "$device" ] && break
    sleep 0.1
done
[ -n "$device" ] || fail "no i2c-dev adapter named 'SMBus stub driver' appeared"
echo "init: stub adapter is $device"

fb=
for _ in 1 2 3 4 5 6 7 8 9 10; do
    for dir in /sys/class/graphics/fb*; do
        [ -r "$dir/name" ] || continue
        if [ "$(cat "$dir/name")" = "Virtual FB" ] && [ -c "/dev/${dir##*/}" ]; then
            fb=/dev/${dir##*/}
        fi
    done
    [ -n "$fb" ] && break
    sleep 0.1
done
[ -n "$fb" ] || fail "no framebuffer named 'Virtual FB' appeared (vfb)"
echo "init: vfb is $fb"
# The kernel's framebuffer console takes over a new framebuffer and would draw its text and
# blinking cursor into the frames read back: unbind it from the virtual terminals.
for con in /sys/class/vtconsole/vtcon*; do
    if grep -q "frame buffer" "$con/name" 2>/dev/null && [ "$(cat "$con/bind")" = 1 ]; then
        echo 0 >"$con/bind" || fail "cannot unbind the framebuffer console ($con)"
        echo "init: unbound $(cat "$con/name") from the virtual terminals"
    fi
done

/bin/caphub-guest "$device" "$fb"
status=$?
if [ $status -eq 0 ]; then
    finish PASS
fi
echo "init: guest program exited with status $status"
finish FAIL

# Cross toolchain for 32-bit ARM boards on Debian armhf (ARMv7, hard float; runs on the Pi 2 and
# later, not on ARMv6 Pi 1 / Zero W): Debian's g++-arm-linux-gnueabihf, a Debian armhf sysroot,
# tests under qemu-arm.
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CAPHUB_CROSS_TRIPLET arm-linux-gnueabihf)
set(CAPHUB_DEB_ARCH armhf)
set(CAPHUB_QEMU qemu-arm)
include("${CMAKE_CURRENT_LIST_DIR}/cross-common.cmake")

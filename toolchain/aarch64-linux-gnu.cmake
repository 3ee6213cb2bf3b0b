# Cross toolchain for 64-bit ARM boards (Raspberry Pi 4 / CM4 / Zero 2 W on a 64-bit OS):
# Debian's g++-aarch64-linux-gnu, a Debian arm64 sysroot, tests under qemu-aarch64.
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CAPHUB_CROSS_TRIPLET aarch64-linux-gnu)
set(CAPHUB_DEB_ARCH arm64)
set(CAPHUB_QEMU qemu-aarch64)
include("${CMAKE_CURRENT_LIST_DIR}/cross-common.cmake")

# Shared part of the cross toolchain files: Debian's cross compiler for CAPHUB_CROSS_TRIPLET, a
# sysroot unpacked from Debian's CAPHUB_DEB_ARCH packages (toolchain/make-sysroot.sh), and
# qemu-user as the emulator, so that ctest runs the unit tests as target binaries.
set(CMAKE_SYSTEM_NAME Linux)

set(CMAKE_C_COMPILER ${CAPHUB_CROSS_TRIPLET}-gcc)
set(CMAKE_CXX_COMPILER ${CAPHUB_CROSS_TRIPLET}-g++)

# The sysroot: a folder, not a multiarch install on the host. The default is where
# make-sysroot.sh puts it; -DCAPHUB_SYSROOT=DIR picks another.
if(NOT CAPHUB_SYSROOT)
    if(DEFINED ENV{CAPHUB_SYSROOT})
        set(CAPHUB_SYSROOT "$ENV{CAPHUB_SYSROOT}")
    else()
        get_filename_component(CAPHUB_SYSROOT
                               "${CMAKE_CURRENT_LIST_DIR}/../build/sysroot/${CAPHUB_DEB_ARCH}" ABSOLUTE)
    endif()
endif()
# try_compile projects re-read this file; they get the sysroot through the environment.
set(ENV{CAPHUB_SYSROOT} "${CAPHUB_SYSROOT}")
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES CAPHUB_SYSROOT)
if(NOT EXISTS "${CAPHUB_SYSROOT}/.caphub-sysroot")
    message(FATAL_ERROR "No ${CAPHUB_DEB_ARCH} sysroot at ${CAPHUB_SYSROOT}: "
                        "run `bash toolchain/make-sysroot.sh ${CAPHUB_DEB_ARCH}` first")
endif()
set(CMAKE_SYSROOT "${CAPHUB_SYSROOT}")

# Libraries, headers and CMake packages come from the sysroot only; programs run on the host.
set(CMAKE_FIND_ROOT_PATH "${CAPHUB_SYSROOT}")
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
set(ENV{PKG_CONFIG_DIR} "")
set(ENV{PKG_CONFIG_LIBDIR}
    "${CAPHUB_SYSROOT}/usr/lib/${CAPHUB_CROSS_TRIPLET}/pkgconfig:${CAPHUB_SYSROOT}/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_SYSROOT_DIR} "${CAPHUB_SYSROOT}")

# The linker resolves the dependencies of shared libraries (libspdlog -> libfmt) in the sysroot.
set(CMAKE_EXE_LINKER_FLAGS_INIT "-Wl,-rpath-link,${CAPHUB_SYSROOT}/usr/lib/${CAPHUB_CROSS_TRIPLET}")
set(CMAKE_SHARED_LINKER_FLAGS_INIT "-Wl,-rpath-link,${CAPHUB_SYSROOT}/usr/lib/${CAPHUB_CROSS_TRIPLET}")

# No binfmt handler is registered on the build machines: run target programs through qemu-user,
# with the sysroot as the root for the dynamic loader and the shared libraries.
find_program(CAPHUB_QEMU_USER ${CAPHUB_QEMU} REQUIRED)
set(CMAKE_CROSSCOMPILING_EMULATOR "${CAPHUB_QEMU_USER};-L;${CAPHUB_SYSROOT}")

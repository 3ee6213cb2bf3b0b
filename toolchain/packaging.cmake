# The caphub .deb (CPack DEB generator): the program, the shipped board files and data folder,
# the systemd unit, udev rules, the default configuration in /etc/caphub (conffiles), and the
# maintainer scripts that create the service user. `cpack -G DEB` in a build folder makes
# caphub_VERSION_ARCH.deb for that build's architecture (amd64 on the host, arm64 and armhf in
# the cross builds). Included from the top-level CMakeLists.txt.

set(caphub_system_dir "${PROJECT_SOURCE_DIR}/firmware/system")

# The board files for real hardware and the config.txt lines each needs (toolchain/caphub-flash
# adds them to the boot partition). The simulated suits are installed by firmware/.
install(FILES "${PROJECT_SOURCE_DIR}/board/rpi4-suit.toml"
              "${PROJECT_SOURCE_DIR}/board/rpi4-suit.config.txt"
              "${PROJECT_SOURCE_DIR}/board/rpi-zero2w-suit.toml"
              "${PROJECT_SOURCE_DIR}/board/rpi-zero2w-suit.config.txt"
              "${PROJECT_SOURCE_DIR}/board/rpi4-spi-suit.toml"
              "${PROJECT_SOURCE_DIR}/board/rpi4-spi-suit.config.txt"
        DESTINATION share/caphub/board)
# The default mesh arrives with the render issue: install it to share/caphub/mesh here.

# The system integration. Debian 12 keeps package units and rules under /lib.
install(FILES "${caphub_system_dir}/caphub.service" DESTINATION /lib/systemd/system)
install(FILES "${caphub_system_dir}/60-caphub.rules" DESTINATION /lib/udev/rules.d)
# Default configuration: the service settings and the board it runs (the Pi 4 suit until the
# image is flashed for another board). dpkg keeps an administrator's changes to both.
install(FILES "${caphub_system_dir}/caphub.conf" DESTINATION /etc/caphub)
install(FILES "${PROJECT_SOURCE_DIR}/board/rpi4-suit.toml" DESTINATION /etc/caphub
        RENAME board.toml)
set(caphub_conffiles /etc/caphub/caphub.conf /etc/caphub/board.toml)
list(JOIN caphub_conffiles "\n" caphub_conffiles_text)
file(WRITE "${PROJECT_BINARY_DIR}/deb/conffiles" "${caphub_conffiles_text}\n")
foreach(script postinst prerm postrm)
    configure_file("${caphub_system_dir}/${script}" "${PROJECT_BINARY_DIR}/deb/${script}" COPYONLY
                   FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE
                                    WORLD_READ WORLD_EXECUTE)
endforeach()

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME caphub)
set(CPACK_PACKAGE_VENDOR "caphub")
set(CPACK_PACKAGE_CONTACT "caphub maintainers <caphub@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGING_INSTALL_PREFIX "/usr")
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
# The extended description only: CPack puts CPACK_PACKAGE_DESCRIPTION_SUMMARY on the first line
# and indents each line of this one by a space.
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "Reads 10-17 9-axis IMUs over I2C/SPI, fuses each into an orientation, drives a\nskeleton, records, previews and exports. Runs as the caphub service.")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    "${PROJECT_BINARY_DIR}/deb/conffiles" "${PROJECT_BINARY_DIR}/deb/postinst"
    "${PROJECT_BINARY_DIR}/deb/prerm" "${PROJECT_BINARY_DIR}/deb/postrm")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# The maintainer scripts call adduser and addgroup; caphub serve's page loads three.js from
# libjs-three (/usr/share/javascript/three).
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser, libjs-three")

# Dependencies come from the shared libraries the program links. On the host dpkg-shlibdeps
# finds them through the dpkg database. A cross build's libraries are in the sysroot, which dpkg
# does not know: toolchain/cpack_shlibdeps.cmake reads the program's DT_NEEDED entries and maps
# each to its package with the shlibs files make-sysroot.sh kept from the sysroot's packages.
if(CMAKE_CROSSCOMPILING)
    set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE "${CAPHUB_DEB_ARCH}")
    set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS OFF)
    set(CPACK_CAPHUB_SYSROOT "${CAPHUB_SYSROOT}")
    set(CPACK_CAPHUB_OBJDUMP "${CMAKE_OBJDUMP}")
    set(CPACK_CAPHUB_PROGRAM "${PROJECT_BINARY_DIR}/bin/caphub")
    set(CPACK_PROJECT_CONFIG_FILE "${CMAKE_CURRENT_LIST_DIR}/cpack_shlibdeps.cmake")
else()
    set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
endif()

include(CPack)

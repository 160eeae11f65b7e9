# Runs at install time (install(CODE) in CMakeLists.txt), so the paths written into the unit follow
# the prefix given to `cmake --install --prefix P`, not the one known at configure time.
# In: PREVIS_UNIT_TEMPLATE, PREVIS_UNIT_WORKDIR, PREVIS_UNITDIR, PREVIS_BINDIR_REL, PREVIS_DOCDIR_REL,
#     PREVIS_CONFDIR_CACHE (empty = derive from the prefix), PREVIS_EXAMPLE_DIR.

# Relative folders are under the prefix; absolute ones (e.g. /lib/systemd/system) stay as given.
function(previs_abs out dir)
    if(IS_ABSOLUTE "${dir}")
        set(${out} "${dir}" PARENT_SCOPE)
    else()
        set(${out} "${CMAKE_INSTALL_PREFIX}/${dir}" PARENT_SCOPE)
    endif()
endfunction()

previs_abs(PREVIS_BINDIR "${PREVIS_BINDIR_REL}")
previs_abs(PREVIS_DOCDIR "${PREVIS_DOCDIR_REL}")
previs_abs(unitdir "${PREVIS_UNITDIR}")

# The config folder, GNUInstallDirs' rule for sysconfdir: /usr installs read /etc, any other
# prefix P reads P/etc (so a /usr/local or scratch install never touches /etc).
if(PREVIS_CONFDIR_CACHE)
    set(PREVIS_CONFDIR "${PREVIS_CONFDIR_CACHE}")
elseif(CMAKE_INSTALL_PREFIX STREQUAL "/usr")
    set(PREVIS_CONFDIR "/etc/previs")
else()
    set(PREVIS_CONFDIR "${CMAKE_INSTALL_PREFIX}/etc/previs")
endif()

# One generated file per destination: installs to different prefixes may run at the same time
# (the tests do).
string(MD5 key "$ENV{DESTDIR}|${CMAKE_INSTALL_PREFIX}|${PREVIS_CONFDIR}")
set(generated "${PREVIS_UNIT_WORKDIR}/${key}/previsd.service")
configure_file("${PREVIS_UNIT_TEMPLATE}" "${generated}" @ONLY)
file(INSTALL "${generated}" DESTINATION "${unitdir}")
file(REMOVE_RECURSE "${PREVIS_UNIT_WORKDIR}/${key}")

# The example config: installed once, never over a config an operator has edited.
file(GLOB example_files RELATIVE "${PREVIS_EXAMPLE_DIR}" "${PREVIS_EXAMPLE_DIR}/*")
foreach(name ${example_files})
    if(EXISTS "$ENV{DESTDIR}${PREVIS_CONFDIR}/${name}")
        message(STATUS "Keeping: $ENV{DESTDIR}${PREVIS_CONFDIR}/${name} (exists; the example is "
                       "${PREVIS_EXAMPLE_DIR}/${name})")
    elseif(IS_SYMLINK "${PREVIS_EXAMPLE_DIR}/${name}")
        # A link inside the repository (examples/box/scene -> ../cubes_spheres) is installed as
        # a copy of what it points at, so the installed config is self-contained.
        file(REAL_PATH "${PREVIS_EXAMPLE_DIR}/${name}" target)
        file(INSTALL "${target}/" DESTINATION "${PREVIS_CONFDIR}/${name}")
    else()
        file(INSTALL "${PREVIS_EXAMPLE_DIR}/${name}" DESTINATION "${PREVIS_CONFDIR}")
    endif()
endforeach()

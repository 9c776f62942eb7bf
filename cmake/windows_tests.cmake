# The Windows tier (label windows): the cross-built module and extension zip of RAYSPLATS_WINDOWS_BUILD
# (scripts/windows/build.sh) run in Windows CPython 3.11 and 3.13 and in Blender 4.2 for Windows, all under Wine
# (scripts/windows/wine_python.sh), and what they make is compared with what the Linux build makes from the same
# inputs under the same Embree instruction set (scripts/windows/compare_platforms.py).
set(RAYSPLATS_WINDOWS_BUILD "" CACHE PATH "A Windows build folder of scripts/windows/build.sh; empty: no Windows tests")
set(RAYSPLATS_WINDOWS_BLENDER_SITE "" CACHE PATH "Blender 4.2 for Windows unpacked (scripts/windows/setup_pythons.sh)")
if(NOT RAYSPLATS_WINDOWS_BUILD)
  raysplats_tier_not_run(windows.not_run
    "no Windows build (RAYSPLATS_WINDOWS_BUILD; scripts/test.sh makes it with scripts/windows/build.sh)" LABELS windows)
  return()
endif()
set(windows_scripts ${PROJECT_SOURCE_DIR}/scripts/windows)
set(compare_dir ${CMAKE_BINARY_DIR}/platforms)
set(isa_env RAYSPLATS_EMBREE_CONFIG=isa=${RAYSPLATS_COMPARE_ISA})
file(STRINGS ${PROJECT_SOURCE_DIR}/addon/raysplats/blender_manifest.toml windows_manifest_version REGEX "^version *=")
string(REGEX REPLACE "^version *= *\"([^\"]+)\".*" "\\1" windows_manifest_version "${windows_manifest_version}")
set(windows_zip ${PROJECT_SOURCE_DIR}/dist/raysplats-${windows_manifest_version}-windows_x64.zip)

add_test(NAME windows.package COMMAND ${windows_scripts}/package.sh --no-build ${RAYSPLATS_WINDOWS_BUILD})
set_tests_properties(windows.package PROPERTIES LABELS "windows;extension" TIMEOUT 300 FIXTURES_SETUP raysplats_windows_zip)

# The module's own tests in each Windows Python, and the platform test on both systems.
foreach(minor 11 13)
  set(pyd_dir ${RAYSPLATS_WINDOWS_BUILD}/native/python/python3${minor})
  set(wine_python ${CMAKE_COMMAND} -E env ${isa_env} ${windows_scripts}/wine_python.sh 3.${minor})
  add_test(NAME windows.py3${minor}.conversions
    COMMAND ${wine_python} ${PROJECT_SOURCE_DIR}/native/python/test_conversions.py ${pyd_dir})
  add_test(NAME windows.py3${minor}.gltf_splats
    COMMAND ${wine_python} ${PROJECT_SOURCE_DIR}/native/python/test_gltf_splats.py ${pyd_dir} ${RAYSPLATS_DATA_DIR})
  add_test(NAME windows.py3${minor}.compressed_ply
    COMMAND ${wine_python} ${PROJECT_SOURCE_DIR}/native/python/test_compressed_ply.py ${pyd_dir}
            ${RAYSPLATS_WINDOWS_BUILD}/native/tools/raysplats.exe ${RAYSPLATS_DATA_DIR}
            ${CMAKE_BINARY_DIR}/windows-tmp-py3${minor})
  add_test(NAME windows.py3${minor}.module_platform
    COMMAND ${wine_python} ${PROJECT_SOURCE_DIR}/native/python/test_module_platform.py ${pyd_dir}
            ${RAYSPLATS_DATA_DIR} ${compare_dir}/windows-py3${minor})
  set_tests_properties(windows.py3${minor}.conversions windows.py3${minor}.gltf_splats
    windows.py3${minor}.compressed_ply windows.py3${minor}.module_platform PROPERTIES LABELS "windows" TIMEOUT 900)
  set_tests_properties(windows.py3${minor}.module_platform PROPERTIES FIXTURES_SETUP raysplats_windows_py3${minor})
  raysplats_skips_with_77(windows.py3${minor}.conversions windows.py3${minor}.gltf_splats
    windows.py3${minor}.compressed_ply windows.py3${minor}.module_platform)
endforeach()
file(MAKE_DIRECTORY ${CMAKE_BINARY_DIR}/windows-tmp-py311 ${CMAKE_BINARY_DIR}/windows-tmp-py313)

# The same platform test with the Linux module of this build (Python 3.11), then the two compared.
add_test(NAME python.module_platform
  COMMAND ${CMAKE_COMMAND} -E env ${isa_env} ${Python_EXECUTABLE}
          ${PROJECT_SOURCE_DIR}/native/python/test_module_platform.py $<TARGET_FILE_DIR:_native> ${RAYSPLATS_DATA_DIR}
          ${compare_dir}/linux-py311)
set_tests_properties(python.module_platform PROPERTIES LABELS "python;windows" TIMEOUT 600
  FIXTURES_SETUP raysplats_linux_platform)
raysplats_skips_with_77(python.module_platform)
foreach(minor 11 13)
  add_test(NAME windows.py3${minor}.agrees_with_linux
    COMMAND ${Python_EXECUTABLE} ${windows_scripts}/compare_platforms.py ${compare_dir}/linux-py311
            ${compare_dir}/windows-py3${minor})
  set_tests_properties(windows.py3${minor}.agrees_with_linux PROPERTIES LABELS "windows" TIMEOUT 120
    FIXTURES_REQUIRED "raysplats_linux_platform;raysplats_windows_py3${minor}")
endforeach()

# The extension zip installed into Blender 4.2 for Windows through Blender's own installer, then used: a real
# scene imported, edited, rendered with meshes and shadows, exported; compared with Blender 4.2 for Linux doing the
# same with the Linux zip (extension.install_bpy4_2, blender_tests/CMakeLists.txt, leaves its outputs in
# ${compare_dir}/linux-bpy4_2).
if(RAYSPLATS_WINDOWS_BLENDER_SITE)
  add_test(NAME windows.bpy4_2.extension_install
    COMMAND ${CMAKE_COMMAND} -E env ${isa_env} ${windows_scripts}/wine_python.sh 3.11 --site ${RAYSPLATS_WINDOWS_BLENDER_SITE}
            ${PROJECT_SOURCE_DIR}/blender_tests/extension/test_extension_install.py --zip ${windows_zip}
            --data-dir ${RAYSPLATS_DATA_DIR} --tmp-dir ${CMAKE_BINARY_DIR}/windows-tmp-bpy4_2
            --out-dir ${compare_dir}/windows-bpy4_2)
  set_tests_properties(windows.bpy4_2.extension_install PROPERTIES LABELS "windows;extension" TIMEOUT 1200
    FIXTURES_REQUIRED raysplats_windows_zip FIXTURES_SETUP raysplats_windows_bpy4_2)
  raysplats_skips_with_77(windows.bpy4_2.extension_install)
  file(MAKE_DIRECTORY ${CMAKE_BINARY_DIR}/windows-tmp-bpy4_2)
  # A Windows render-farm worker: farm/install_worker.py run by Windows CPython 3.11 installs the zip into a user
  # folder given in Windows' form and checks that Blender 4.2 for Windows renders with it; and its refusals.
  add_test(NAME windows.bpy4_2.install_worker
    COMMAND ${Python_EXECUTABLE} ${PROJECT_SOURCE_DIR}/farm/tests/test_install_worker.py --zip ${windows_zip}
            --data-dir ${RAYSPLATS_DATA_DIR} --wine-site ${RAYSPLATS_WINDOWS_BLENDER_SITE}
            --tmp-dir ${CMAKE_BINARY_DIR}/windows-tmp-install-worker)
  set_tests_properties(windows.bpy4_2.install_worker PROPERTIES LABELS "windows;farm;extension" TIMEOUT 600
    FIXTURES_REQUIRED raysplats_windows_zip)
  raysplats_skips_with_77(windows.bpy4_2.install_worker)
  if(RAYSPLATS_EXTRA_PYTHON AND RAYSPLATS_BPY_PYTHONS MATCHES "(^|;)4\\.2=")
    add_test(NAME windows.bpy4_2.agrees_with_linux
      COMMAND ${Python_EXECUTABLE} ${windows_scripts}/compare_platforms.py ${compare_dir}/linux-bpy4_2
              ${compare_dir}/windows-bpy4_2)
    set_tests_properties(windows.bpy4_2.agrees_with_linux PROPERTIES LABELS "windows" TIMEOUT 120
      FIXTURES_REQUIRED "raysplats_windows_bpy4_2;raysplats_linux_bpy4_2")
  endif()
endif()

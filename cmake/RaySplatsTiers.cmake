# Tiers of the test suite that CMake cannot register on this machine (no Blender, no xvfb-run, no node, no second
# Python module...) and how tests report skips (docs/building.md, "Strict mode, skips and the summary").
#
# raysplats_tier_not_run(NAME "why" [LABELS labels...]) adds a ctest test NAME in place of the missing tier, run by
# scripts/lib/tier_not_run.sh: under strict mode (CI=true or RAYSPLATS_STRICT=1, read when ctest runs) it fails naming
# the tier; otherwise it skips (exit 77) with the reason, which the test command's summary shows. A reason starting
# with "expected: " is something this machine lacks by design and skips under strict mode too.
#
# raysplats_skips_with_77(TESTS...) marks tests whose runner exits 77 when every test inside skipped
# (scripts/lib/unittest_report.py, scripts/lib/run_gtest.py) so that ctest counts them as skipped, not passed.
set(RAYSPLATS_SKIP_RETURN_CODE 77)

function(raysplats_tier_not_run name why)
  cmake_parse_arguments(arg "" "" "LABELS" ${ARGN})
  add_test(NAME ${name} COMMAND ${PROJECT_SOURCE_DIR}/scripts/lib/tier_not_run.sh ${name} "${why}")
  set_tests_properties(${name} PROPERTIES SKIP_RETURN_CODE ${RAYSPLATS_SKIP_RETURN_CODE} LABELS "${arg_LABELS}")
endfunction()

function(raysplats_skips_with_77)
  set_tests_properties(${ARGN} PROPERTIES SKIP_RETURN_CODE ${RAYSPLATS_SKIP_RETURN_CODE})
endfunction()

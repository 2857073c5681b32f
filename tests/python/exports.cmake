# Python tests of the exports, streamlines and pictures (client/python/fieldspace/{fields,export,
# streamlines,render,display}.py). Included from tests/python/CMakeLists.txt. They run with
# Debian's /usr/bin/python3 (numpy, python3-vtk9, python3-meshio, xvfb); exit code 77 = every
# test skipped because a dependency is missing. test_fields also compares with field files that
# the C++ CLI writes against a daemon it starts (FIELDSPACE_BIN_DIR).
foreach(name fields export streamlines render)
  add_test(NAME python_exports_${name}
    COMMAND /usr/bin/python3 ${CMAKE_CURRENT_LIST_DIR}/test_${name}.py)
  set_tests_properties(python_exports_${name} PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 600
    ENVIRONMENT "FIELDSPACE_BIN_DIR=$<TARGET_FILE_DIR:fieldspaced>;PYTHONPATH=${FIELDSPACE_PYTHON_DIR}")
endforeach()

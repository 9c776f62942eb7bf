# Cross-compiling for 64-bit Windows with Debian's MinGW-w64 (g++-mingw-w64-x86-64-posix: GCC 12 with POSIX
# threads, the thread model std::thread and TBB need). Used for the Windows dependencies (scripts/windows/build_deps.sh)
# and for the module itself (scripts/windows/build.sh).
set(CMAKE_SYSTEM_NAME Windows)
set(CMAKE_SYSTEM_PROCESSOR AMD64)
set(CMAKE_C_COMPILER x86_64-w64-mingw32-gcc-posix)
set(CMAKE_CXX_COMPILER x86_64-w64-mingw32-g++-posix)
set(CMAKE_RC_COMPILER x86_64-w64-mingw32-windres)
set(CMAKE_AR x86_64-w64-mingw32-ar CACHE FILEPATH "")
set(CMAKE_RANLIB x86_64-w64-mingw32-ranlib CACHE FILEPATH "")
# The Windows x64 ABI only promises a 16-byte aligned stack, and GCC does not realign it for 32-byte AVX spills
# (GCC bug 54412): an aligned vmovaps of a spilled __m256 then faults. The assembler option turns every aligned
# vector move into its unaligned form, which costs nothing on any CPU with AVX.
set(CMAKE_C_FLAGS_INIT "-Wa,-muse-unaligned-vector-move")
set(CMAKE_CXX_FLAGS_INIT "-Wa,-muse-unaligned-vector-move")
# Only MinGW's own prefix and the prefix of the cross-built dependencies (the environment's RAYSPLATS_WINDOWS_PREFIX,
# set by scripts/windows/*.sh) are searched for libraries, headers and CMake packages, never the build machine's /usr.
set(CMAKE_FIND_ROOT_PATH /usr/x86_64-w64-mingw32 $ENV{RAYSPLATS_WINDOWS_PREFIX})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

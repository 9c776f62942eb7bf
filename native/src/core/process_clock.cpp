#include "core/process_clock.h"

#include <chrono>

#ifdef _WIN32
#include "core/windows_api.h"
#else
#include <time.h>
#endif

namespace raysplats {

double process_cpu_seconds() {
#ifdef _WIN32
    FILETIME creation, exit, kernel, user;
    if (!GetProcessTimes(GetCurrentProcess(), &creation, &exit, &kernel, &user)) return 0.0;
    auto ticks = [](const FILETIME& t) { return (unsigned long long)t.dwHighDateTime << 32 | t.dwLowDateTime; };
    return double(ticks(kernel) + ticks(user)) * 1e-7;  // FILETIME counts 100 ns
#else
    timespec t{};
    if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t) != 0) return 0.0;
    return double(t.tv_sec) + double(t.tv_nsec) * 1e-9;
#endif
}

namespace {
double wall_seconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

PhaseClock::PhaseClock(double& wall_total, double& cpu_total)
    : wall_total_(wall_total), cpu_total_(cpu_total), wall_start_(wall_seconds()), cpu_start_(process_cpu_seconds()) {}

void PhaseClock::stop() {
    wall_total_ += wall_seconds() - wall_start_;
    cpu_total_ += process_cpu_seconds() - cpu_start_;
}

}  // namespace raysplats

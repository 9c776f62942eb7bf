// The CPU time this process has used so far, every thread's, user and system: what a render phase run on all cores
// costs the machine, as opposed to its wall time.
#pragma once

namespace raysplats {

// Seconds of CPU used by the whole process (POSIX CLOCK_PROCESS_CPUTIME_ID; Windows GetProcessTimes, kernel plus
// user). Differences of two calls time a phase; other threads of the process running meanwhile count too.
double process_cpu_seconds();

// Wall and CPU seconds from construction to stop(), added to the two totals given.
class PhaseClock {
public:
    PhaseClock(double& wall_total, double& cpu_total);
    void stop();

private:
    double& wall_total_;
    double& cpu_total_;
    double wall_start_;
    double cpu_start_;
};

}  // namespace raysplats

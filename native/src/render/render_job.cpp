// RenderJob and SharedScene (raysplats/render/render_job.h).
#include "raysplats/render/render_job.h"

#include <algorithm>
#include <chrono>
#include <string>

#include <tbb/task_arena.h>

#if defined(__linux__)
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#elif defined(_WIN32)
#include "core/windows_api.h"
#endif

#include "raysplats/errors.h"

namespace raysplats {
namespace {

// A hint (failures ignored): the thread gets less CPU than normal ones when they compete. Linux nice +10 weighs
// 110 against a normal thread's 1024 (sched_prio_to_weight); other systems keep the normal priority.
void lower_this_threads_priority() {
#if defined(__linux__)
    setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), 10);
#elif defined(_WIN32)
    SetThreadPriority(GetCurrentThread(), THREAD_PRIORITY_BELOW_NORMAL);
#endif
}

}  // namespace

SharedScene::Change SharedScene::change() {
    int idle = 0;
    if (!state_.compare_exchange_strong(idle, -1)) {
        if (idle > 0)
            throw Error("the scene is being rendered; wait for or cancel the render before changing it");
        throw Error("the scene is being changed by another thread");
    }
    return Change(this);
}

void SharedScene::begin_render() {
    int jobs = state_.load();
    do {
        if (jobs < 0) throw Error("the scene is being changed; render it once the change is done");
    } while (!state_.compare_exchange_weak(jobs, jobs + 1));
}

RenderJob::RenderJob(SharedScene& scene, const Camera& camera, const RenderSettings& settings, int max_threads,
                     bool below_normal_priority)
    : scene_(scene),
      camera_(camera),
      settings_(settings),
      max_threads_(max_threads),
      below_normal_priority_(below_normal_priority) {
    camera_.validate();
    settings_.validate();
    if (max_threads < 0) throw InvalidArgument("render job: max_threads must be >= 0 (0: all), got " + std::to_string(max_threads));
    scene_.begin_render();
    try {
        thread_ = std::thread([this] {
            try {
                // The scene is busy, so nothing else changes it; render() may still build its BVH.
                // The BVH first, on every core at normal priority: after an edit it is what the first image
                // waits for, and built by the capped, lowered render threads under load it took many times longer.
                // render() then finds it built.
                {
                    std::lock_guard<std::mutex> lock(scene_.build_mutex_);
                    scene_.scene_.build(settings_.gaussian_mode);
                }
                if (below_normal_priority_) lower_this_threads_priority();
                auto run = [this] {
                    film_ = render(scene_.scene_, camera_, settings_, [this](float f) { progress_.store(f); }, &cancel_,
                                   [this](const Film& film_so_far) {
                                       // Copied outside the lock, which is held only to swap: a reader
                                       // (the UI thread) never waits for this thread's copy, which may run
                                       // at low priority (below_normal_priority).
                                       spare_snapshot_ = film_so_far;  // reuses the buffers of an older copy
                                       std::lock_guard<std::mutex> lock(snapshot_mutex_);
                                       std::swap(snapshot_, spare_snapshot_);
                                       snapshot_samples_.store(film_so_far.stats.samples);
                                   });
                };
                if (max_threads_ > 0)
                    tbb::task_arena(max_threads_).execute(run);
                else
                    run();
            } catch (...) {
                error_ = std::current_exception();
            }
            scene_.end_render();
            std::lock_guard<std::mutex> lock(mutex_);
            done_ = true;
            ended_.notify_all();
        });
    } catch (...) {  // no thread: the scene is not rendered after all
        scene_.end_render();
        throw;
    }
}

RenderJob::~RenderJob() {
    cancel_.store(true);
    if (thread_.joinable()) thread_.join();
}

bool RenderJob::wait(double timeout_seconds) {
    std::unique_lock<std::mutex> lock(mutex_);
    // A timeout beyond ~100 days (or NaN) means no timeout: converted to the clock's nanoseconds, centuries
    // would overflow.
    if (!(timeout_seconds < 1e7)) {
        ended_.wait(lock, [this] { return done_; });
        return true;
    }
    const auto timeout = std::chrono::duration<double>(std::max(0.0, timeout_seconds));
    return ended_.wait_for(lock, timeout, [this] { return done_; });
}

Film RenderJob::snapshot(const std::vector<FilmChannel>& channels) const {
    std::lock_guard<std::mutex> lock(snapshot_mutex_);
    if (channels.empty()) return snapshot_;
    Film film;
    film.width = snapshot_.width, film.height = snapshot_.height, film.stats = snapshot_.stats;
    for (FilmChannel channel : channels) film[channel] = snapshot_[channel];
    // (The Cryptomatte passes are not film channels: copied whenever the render has them.)
    film.cryptomatte = snapshot_.cryptomatte;
    film.cryptomatte_ranks = snapshot_.cryptomatte_ranks;
    return film;
}

Film RenderJob::result() {
    {
        std::unique_lock<std::mutex> lock(mutex_);
        ended_.wait(lock, [this] { return done_; });
    }
    if (thread_.joinable()) thread_.join();
    if (result_taken_) throw Error("the render's result was already taken");
    result_taken_ = true;
    if (error_) std::rethrow_exception(error_);
    return std::move(film_);
}

}  // namespace raysplats

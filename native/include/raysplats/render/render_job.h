// A render on a thread of its own, for front ends that must stay responsive while it runs (Blender's engine
// polls progress and Esc from its main thread): start it, poll progress(), cancel(), wait(), take result().
// While it runs, snapshot() gives the image of the sample passes done so far (progressive display).
//
// The job reads its scene on its own thread, so the scene must not change meanwhile. A SharedScene is a Scene
// with the count of the jobs rendering it: changes go through SharedScene::change(), which refuses (throws
// Error) while a job runs, and a job refuses to start while a change is under way.
#pragma once

#include <atomic>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "raysplats/render/renderer.h"

namespace raysplats {

class SharedScene {
public:
    // Reading is always allowed (counts, the last build's report); the scene must outlive every job on it.
    const Scene& scene() const { return scene_; }
    // True while a RenderJob renders this scene.
    bool busy() const { return state_.load() > 0; }

    // Exclusive access for one change; throws Error while a job renders the scene (or another change runs).
    class Change {
    public:
        Scene* operator->() const { return &owner_->scene_; }
        Scene& operator*() const { return owner_->scene_; }
        Change(const Change&) = delete;
        Change& operator=(const Change&) = delete;
        ~Change() { owner_->state_.store(0); }

    private:
        friend class SharedScene;
        explicit Change(SharedScene* owner) : owner_(owner) {}
        SharedScene* owner_;
    };
    Change change();

private:
    friend class RenderJob;
    void begin_render();  // throws while a change runs
    void end_render() { --state_; }

    Scene scene_;
    std::atomic<int> state_{0};  // > 0: jobs rendering; -1: a change under way; 0: idle
    // Jobs may overlap (the viewport starts one while a cancelled one ends): one builds the BVH at a time, and the
    // others then find it built (Scene::build writes nothing then).
    std::mutex build_mutex_;
};

class RenderJob {
public:
    // Validates the camera and settings (throws InvalidArgument here, on the caller's thread), then starts
    // rendering `scene` on a new thread. The scene counts as busy until the render has ended.
    // For an interactive front end, whose UI otherwise competes with every core of the render: `max_threads` > 0
    // caps the threads the render uses (a TBB arena of that concurrency, the job's own thread included), and
    // `below_normal_priority` lowers the priority of the job's own thread (Linux nice +10, Windows below normal; not
    // of TBB's workers, which are shared and could not be raised back without privileges); both apply to the
    // sampling, not to the scene's BVH build, which runs first on every core. Blender's viewport uses both: all cores
    // but one, and its one thread on 2 cores yields to the UI's drawing.
    RenderJob(SharedScene& scene, const Camera& camera, const RenderSettings& settings, int max_threads = 0,
              bool below_normal_priority = false);
    // Cancels the render and waits for its thread.
    ~RenderJob();
    RenderJob(const RenderJob&) = delete;
    RenderJob& operator=(const RenderJob&) = delete;

    // Fraction done in [0, 1]; 1 once every tile is rendered.
    float progress() const { return progress_.load(); }
    // Asks the render to stop; it ends within a fraction of a second (render()'s contract) with a film marked
    // cancelled that holds the sample passes done so far.
    void cancel() { cancel_.store(true); }
    // Sample passes completed over the whole image so far, before the last (whose film is the result): the
    // stats.samples of the film snapshot() would return now; 0 before the first pass ends.
    int snapshot_samples() const { return snapshot_samples_.load(); }
    // A copy of the film of the newest completed pass (render()'s SamplePassCallback): of `channels` only when
    // given (the others left empty, size 0), else of every channel; an empty 0 x 0 film before the first pass ends.
    Film snapshot(const std::vector<FilmChannel>& channels = {}) const;
    // Waits at most `timeout_seconds` (any value; huge ones wait for the end); true once the render has ended
    // (finished, cancelled or failed).
    bool wait(double timeout_seconds);
    // Waits for the end and hands the film over (once: a second call throws Error). An exception the render
    // threw is rethrown here.
    Film result();

private:
    SharedScene& scene_;
    const Camera camera_;
    const RenderSettings settings_;
    const int max_threads_;
    const bool below_normal_priority_;
    Film film_;
    std::exception_ptr error_;
    bool result_taken_ = false;
    std::atomic<float> progress_{0.0f};
    std::atomic<bool> cancel_{false};
    mutable std::mutex snapshot_mutex_;
    Film snapshot_;        // guarded by snapshot_mutex_
    Film spare_snapshot_;  // the render thread's: the next pass is copied here, then swapped in
    std::atomic<int> snapshot_samples_{0};
    std::mutex mutex_;
    std::condition_variable ended_;
    bool done_ = false;  // guarded by mutex_
    std::thread thread_;
};

}  // namespace raysplats

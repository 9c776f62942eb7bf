// RenderJob: a render on its own thread, as the Blender engine drives it (raysplats/render/render_job.h).
#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "raysplats/errors.h"
#include "raysplats/render/render_job.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

Camera looking_at_origin() {
    Camera c;
    c.camera_to_world = Matrix4::look_at({0, 0, 4}, {0, 0, 0}, {0, 1, 0});
    return c;
}

RenderSettings settings(int size, int samples) {
    RenderSettings s;
    s.width = s.height = size;
    s.samples = samples;
    s.tile_size = 8;
    return s;
}

// Scenes keep clouds by pointer: these outlive every test's scene.
const GaussianCloud& slow_cloud() {
    static const GaussianCloud cloud = random_cloud(5, 2000, 1.0f);
    return cloud;
}
const GaussianCloud& quick_cloud() {
    static const GaussianCloud cloud = random_cloud(7, 300, 1.0f);
    return cloud;
}

// Content whose render takes minutes unless cancelled (at 128 x 128, 100000 samples).
void add_slow_content(SharedScene& scene) { scene.change()->add_gaussians(slow_cloud()); }

}  // namespace

TEST(RenderJob, FinishesWithProgressOneAndTheImageRenderGives) {
    SharedScene scene;
    scene.change()->add_gaussians(quick_cloud());
    RenderJob job(scene, looking_at_origin(), settings(32, 2));
    EXPECT_TRUE(job.wait(1e300));  // no overflow: waits for the end
    EXPECT_TRUE(job.wait(-1.0));
    EXPECT_FLOAT_EQ(job.progress(), 1.0f);
    const Film film = job.result();
    EXPECT_FALSE(film.stats.cancelled);

    // The same image as render() on the caller's thread: the job only moves the work.
    Scene direct;
    direct.add_gaussians(quick_cloud());
    const Film expected = render(direct, looking_at_origin(), settings(32, 2));
    EXPECT_TRUE(film.channels == expected.channels);
    EXPECT_THROW(job.result(), Error);  // handed over once
}

TEST(RenderJob, CancelReturnsPromptlyWithACancelledFilm) {
    SharedScene scene;
    add_slow_content(scene);
    const auto started = Clock::now();
    RenderJob job(scene, looking_at_origin(), settings(128, 100000));
    // The reference, measured in this run under whatever load the machine has: the time to the first whole pass
    // (the BVH build included). The cancel flag is polled per tile, so a cancel ends the job within one pass; the
    // bound is 3 passes, room for the load to change between the two measurements, plus 1 s for the threads'
    // wake-ups, which do not scale with the pass. The wait is a hang guard only.
    while (job.snapshot_samples() < 1 && !job.wait(0.005) && seconds_since(started) < 300.0) {
    }
    const double first_pass = seconds_since(started);
    ASSERT_GE(job.snapshot_samples(), 1) << "no pass done in " << first_pass << " s";
    EXPECT_FALSE(job.wait(0.0));  // 100000 samples: minutes of work
    const auto start = Clock::now();
    job.cancel();
    const Film film = job.result();
    EXPECT_LT(seconds_since(start), 3.0 * first_pass + 1.0) << "one pass took " << first_pass << " s in this run";
    EXPECT_TRUE(film.stats.cancelled);
    EXPECT_EQ(film.width, 128);
    EXPECT_LT(job.progress(), 1.0f);
}

TEST(RenderJob, DestroyingARunningJobCancelsIt) {
    SharedScene scene;
    add_slow_content(scene);
    const auto started = Clock::now();
    Clock::time_point start;
    double first_pass = 0.0;
    {
        RenderJob job(scene, looking_at_origin(), settings(128, 100000));
        // The bound, as in CancelReturnsPromptlyWithACancelledFilm: 3 times the first pass of this run, plus 1 s.
        while (job.snapshot_samples() < 1 && !job.wait(0.005) && seconds_since(started) < 300.0) {
        }
        first_pass = seconds_since(started);
        ASSERT_GE(job.snapshot_samples(), 1) << "no pass done in " << first_pass << " s";
        EXPECT_FALSE(job.wait(0.0));
        start = Clock::now();
    }
    EXPECT_LT(seconds_since(start), 3.0 * first_pass + 1.0) << "one pass took " << first_pass << " s in this run";
    EXPECT_FALSE(scene.busy());
}

TEST(RenderJob, AnErrorInTheRenderIsRethrownByResult) {
    SharedScene scene;
    // Material 5 does not exist: the scene's build, inside the render on the job's thread, throws.
    const TestMesh quad = make_quad_z(-1, 1, -1, 1, 0, 5);
    scene.change()->add_mesh(quad.desc());
    RenderJob job(scene, looking_at_origin(), settings(16, 1));
    EXPECT_TRUE(job.wait(60.0));
    try {
        job.result();
        FAIL() << "result() did not rethrow the render's error";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("material 5 does not exist"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(scene.busy());
}

TEST(RenderJob, BadSettingsThrowOnTheCallersThreadAndLeaveTheSceneIdle) {
    SharedScene scene;
    EXPECT_THROW(RenderJob(scene, looking_at_origin(), settings(0, 1)), InvalidArgument);
    Camera bad = looking_at_origin();
    bad.focal_length_mm = -1.0f;
    EXPECT_THROW(RenderJob(scene, bad, settings(8, 1)), InvalidArgument);
    EXPECT_FALSE(scene.busy());
    EXPECT_NO_THROW(scene.change()->set_world(World{}));
}

TEST(RenderJob, TheSceneIsBusyWhileRenderingAndRefusesChanges) {
    SharedScene scene;
    add_slow_content(scene);
    EXPECT_FALSE(scene.busy());
    {
        RenderJob job(scene, looking_at_origin(), settings(128, 100000));
        EXPECT_TRUE(scene.busy());
        try {
            scene.change();
            FAIL() << "a change was allowed during a render";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("being rendered"), std::string::npos) << e.what();
        }
        EXPECT_EQ(scene.scene().gaussian_count(), 2000u);  // reading is allowed
        job.cancel();
        job.result();
        EXPECT_FALSE(scene.busy());
    }
    EXPECT_NO_THROW(scene.change()->set_world(World{}));
}

TEST(RenderJob, NoRenderStartsDuringAChange) {
    SharedScene scene;
    add_slow_content(scene);
    auto change = scene.change();
    EXPECT_THROW(RenderJob(scene, looking_at_origin(), settings(8, 1)), Error);
    EXPECT_THROW(scene.change(), Error);  // nor a second change
}

// A job capped to one thread below normal priority (the viewport's, leaving the CPU to Blender's UI) renders the
// same image as one on all threads.
TEST(RenderJob, AThreadCapChangesNothingButTheThreads) {
    SharedScene scene;
    scene.change()->add_gaussians(quick_cloud());
    RenderJob all(scene, looking_at_origin(), settings(32, 2));
    RenderJob one(scene, looking_at_origin(), settings(32, 2), 1, true);
    EXPECT_TRUE(one.result().channels == all.result().channels);
    EXPECT_THROW(RenderJob(scene, looking_at_origin(), settings(32, 2), -1), InvalidArgument);
}

// Progressive rendering (renderer.h's sample passes, render_job.h's snapshot): the film after each pass, a
// cancelled render's film, and the Gaussian-count channel.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <vector>

#include "raysplats/render/render_job.h"
#include "raysplats/render/renderer.h"
#include "render_test_util.h"

using namespace raysplats;
using namespace raysplats::testing;

namespace {

Camera looking_at_origin() {
    Camera c;
    c.camera_to_world = Matrix4::look_at({0, 0, 4}, {0, 0, 0}, {0, 1, 0});
    return c;
}

RenderSettings small_settings(int samples) {
    RenderSettings s;
    s.width = 40;
    s.height = 24;  // not a multiple of the tile size: partial tiles too
    s.tile_size = 16;
    s.samples = samples;
    return s;
}

const GaussianCloud& cloud() {
    static const GaussianCloud c = random_cloud(11, 400, 1.0f);
    return c;
}

}  // namespace

// After pass k the film is exactly the render of k samples (every channel, bit for bit): a pixel's samples and the
// order of their sums do not depend on the pass structure.
TEST(RenderProgressive, EachPassFilmEqualsARenderOfThatManySamples) {
    Scene scene;
    scene.add_gaussians(cloud());
    std::vector<Film> passes;
    const Film final_film = render(scene, looking_at_origin(), small_settings(4), {}, nullptr,
                                   [&](const Film& film) { passes.push_back(film); });
    ASSERT_EQ(passes.size(), 3u);  // after passes 1, 2 and 3; the 4th is the result
    EXPECT_EQ(final_film.stats.samples, 4);
    for (int k = 1; k <= 3; ++k) {
        const Film& film = passes[std::size_t(k - 1)];
        EXPECT_EQ(film.stats.samples, k);
        const Film expected = render(scene, looking_at_origin(), small_settings(k));
        for (const FilmChannelInfo& info : film_channels())
            EXPECT_TRUE(film[info.channel] == expected[info.channel]) << "pass " << k << " channel " << info.key;
    }
    // The passes refine: the 1-sample film differs from the 4-sample one.
    EXPECT_FALSE(passes[0].rgba() == final_film.rgba());
}

// Cancelled between passes, the film keeps the passes done (Cycles' Esc), not an empty image.
TEST(RenderProgressive, ACancelledRenderKeepsTheCompletedPasses) {
    Scene scene;
    scene.add_gaussians(cloud());
    std::atomic<bool> cancel{false};
    const Film film = render(scene, looking_at_origin(), small_settings(50), {}, &cancel, [&](const Film& so_far) {
        if (so_far.stats.samples == 2) cancel = true;
    });
    EXPECT_TRUE(film.stats.cancelled);
    EXPECT_EQ(film.stats.samples, 2);
    const Film expected = render(scene, looking_at_origin(), small_settings(2));
    for (const FilmChannelInfo& info : film_channels())
        EXPECT_TRUE(film[info.channel] == expected[info.channel]) << info.key;
}

// A cancel in the middle of a pass: every tile holds the mean of the passes it completed, k or k + 1 of them.
TEST(RenderProgressive, ACancelMidPassLeavesEveryTileWholePasses) {
    Scene scene;
    scene.add_gaussians(cloud());
    std::atomic<bool> cancel{false};
    std::atomic<int> tile_passes{0};
    RenderSettings s = small_settings(50);
    const int tiles = 3 * 2;
    // Cancelled after 2 passes and half of the third.
    const Film film = render(scene, looking_at_origin(), s, [&](float) {
        if (++tile_passes == 2 * tiles + tiles / 2) cancel = true;
    }, &cancel);
    EXPECT_TRUE(film.stats.cancelled);
    EXPECT_EQ(film.stats.samples, 2);
    const Film two = render(scene, looking_at_origin(), small_settings(2));
    const Film three = render(scene, looking_at_origin(), small_settings(3));
    int tiles_with_three = 0;
    for (int ty = 0; ty < 24; ty += 16)
        for (int tx = 0; tx < 40; tx += 16) {
            bool as_two = true, as_three = true;
            for (int y = ty; y < std::min(ty + 16, 24); ++y)
                for (int x = tx; x < std::min(tx + 16, 40); ++x)
                    for (int c = 0; c < 4; ++c) {
                        const std::size_t i = 4 * (std::size_t(y) * 40 + x) + c;
                        as_two &= film.rgba()[i] == two.rgba()[i];
                        as_three &= film.rgba()[i] == three.rgba()[i];
                    }
            EXPECT_TRUE(as_two || as_three) << "tile at " << tx << "," << ty;
            tiles_with_three += as_three && !as_two;
        }
    EXPECT_GE(tiles_with_three, 1);
}

// The job's snapshot is the newest pass's film; the Python engine polls it to show F12 and the viewport refining.
TEST(RenderProgressive, JobSnapshotsFollowThePasses) {
    SharedScene scene;
    scene.change()->add_gaussians(cloud());
    RenderJob job(scene, looking_at_origin(), small_settings(3));
    ASSERT_TRUE(job.wait(60.0));
    EXPECT_EQ(job.snapshot_samples(), 2);  // the last pass before the result
    const Film snapshot = job.snapshot();
    EXPECT_EQ(snapshot.stats.samples, 2);
    Scene direct;
    direct.add_gaussians(cloud());
    EXPECT_TRUE(snapshot.rgba() == render(direct, looking_at_origin(), small_settings(2)).rgba());
    EXPECT_EQ(job.result().stats.samples, 3);
}

TEST(RenderProgressive, JobSnapshotIsEmptyBeforeTheFirstPass) {
    SharedScene scene;
    scene.change()->add_gaussians(cloud());
    RenderJob job(scene, looking_at_origin(), small_settings(1));  // one pass: its film is the result
    ASSERT_TRUE(job.wait(60.0));
    EXPECT_EQ(job.snapshot_samples(), 0);
    EXPECT_EQ(job.snapshot().width, 0);
}

// The Gaussian-count pass: a ray through n stacked translucent Gaussians composites all n in sorted mode; in
// stochastic mode it accepts at most one, with probability 1 - prod(1 - a).
TEST(RenderProgressive, GaussianCountChannelCountsTheCameraRaysGaussians) {
    GaussianCloud stack;
    const float q[4] = {1, 0, 0, 0}, scale[3] = {5.0f, 5.0f, 0.01f}, rgb[3] = {0.5f, 0.5f, 0.5f};
    const int n = 5;
    for (int i = 0; i < n; ++i) {
        const float pos[3] = {0.0f, 0.0f, -0.2f * i};
        add_gaussian(stack, pos, q, scale, 0.2f, rgb);
    }
    Scene scene;
    scene.add_gaussians(stack);
    RenderSettings s = small_settings(1);
    s.width = s.height = 8;
    s.jitter = false;
    const Film sorted = render(scene, looking_at_origin(), s);
    for (float count : sorted.gaussian_count()) EXPECT_EQ(count, float(n));
    s.compositing = Compositing::Stochastic;
    s.samples = 64;
    const Film stochastic = render(scene, looking_at_origin(), s);
    double mean = 0.0;
    for (float count : stochastic.gaussian_count()) {
        EXPECT_LE(count, 1.0f);
        mean += count / double(stochastic.pixel_count());
    }
    // Acceptance probability 1 - 0.8^5 = 0.672 (the centre of each Gaussian: 5-sigma disks over a 0.8 wide view
    // lose at most exp(-0.5 * 0.1^2) of their alpha); 4096 draws, sd 0.007.
    EXPECT_NEAR(mean, 1.0 - std::pow(0.8, 5), 0.03);
}

// Interactive updates (Scene::update_gaussians / update_mesh): an updated scene renders exactly what a scene built
// from scratch with the new data renders, and the build redoes only what changed.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "raysplats/errors.h"
#include "raysplats/render/renderer.h"
#include "render_test_util.h"

namespace raysplats {
namespace {

using namespace testing;

RenderSettings settings(GaussianMode mode, Compositing compositing) {
    RenderSettings s;
    s.width = 48;
    s.height = 40;
    s.samples = 1;
    s.jitter = false;
    s.max_bounces = 1;
    s.gaussian_mode = mode;
    s.compositing = compositing;
    s.gather_buffer_size = 8;  // re-traces happen, across chunk boundaries too
    s.transparent_background = true;
    return s;
}

Camera test_camera() {
    Camera cam;
    cam.camera_to_world = Matrix4::look_at({0.3f, -0.4f, 4.0f}, {0, 0, 0}, {0, 1, 0});
    cam.focal_length_mm = 35.0f;
    return cam;
}

// A scene with one cloud and one mesh, interactive with small chunks (the cloud has several).
struct TestScene {
    Scene scene;
    explicit TestScene(bool interactive) {
        if (interactive) scene.set_interactive(true, 64);
        scene.set_world(black_world());
        scene.add_material(emissive(0.2f, 0.7f, 0.4f));
    }
};

double max_difference(const Film& a, const Film& b) {
    double m = 0;
    for (std::size_t i = 0; i < a.rgba().size(); ++i) m = std::max(m, double(std::abs(a.rgba()[i] - b.rgba()[i])));
    return m;
}

// Moves Gaussian i by (dx, 0, 0).
void nudge(GaussianCloud& c, std::size_t i, float dx) { c.positions[3 * i] += dx; }

}  // namespace

// Editing a few Gaussians rebuilds only their chunks; moving the object rebuilds nothing but transforms; the
// images equal those of scenes built from scratch with the same data (bit for bit: the same primitives, BVHs
// differ only in which chunks were rebuilt, and compositing is exact). Both modes, sorted and stochastic.
TEST(RenderUpdate, UpdatedGaussiansRenderLikeAFreshScene) {
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric})
        for (Compositing comp : {Compositing::Sorted, Compositing::Stochastic}) {
            const GaussianCloud original = random_cloud(7, 400, 1.0f);
            const TestMesh floor = make_quad_z(-1.5f, 1.5f, -1.5f, 1.5f, -0.6f, 0);
            TestScene live(true);
            live.scene.add_mesh(floor.desc());
            GaussianCloud current = original;
            live.scene.add_gaussians(current);
            live.scene.build(mode);
            EXPECT_TRUE(live.scene.last_build().full);
            EXPECT_EQ(live.scene.last_build().gaussian_chunks, 7u);  // 400 / 64, rounded up

            // Edit: two Gaussians of chunk-position 0..63 move (primitives are in Morton order, so find where they
            // landed by rendering rather than by index: only the count of rebuilt chunks is checked).
            GaussianCloud edited = original;
            nudge(edited, 5, 0.05f);
            nudge(edited, 6, -0.03f);
            const Matrix4 moved = Matrix4::translation(0.1f, -0.05f, 0.2f) * Matrix4::rotation(0.3f, 0, 0, 1);
            live.scene.update_gaussians(0, edited, moved);
            live.scene.build(mode);
            const Scene::BuildReport report = live.scene.last_build();
            EXPECT_FALSE(report.full);
            EXPECT_GE(report.gaussian_chunks, 1u);
            EXPECT_LE(report.gaussian_chunks, 2u);  // the chunks holding Gaussians 5 and 6
            EXPECT_EQ(report.meshes, 0u);
            const Film updated = render(live.scene, test_camera(), settings(mode, comp));

            TestScene fresh(true);
            fresh.scene.add_mesh(floor.desc());
            fresh.scene.add_gaussians(edited, moved);
            const Film expected = render(fresh.scene, test_camera(), settings(mode, comp));
            EXPECT_LE(max_difference(updated, expected), 1e-6) << "mode " << int(mode) << " comp " << int(comp);
            // And the edit is visible: the image differs from the one before it.
            TestScene before(true);
            before.scene.add_mesh(floor.desc());
            before.scene.add_gaussians(original);
            EXPECT_GT(max_difference(updated, render(before.scene, test_camera(), settings(mode, comp))), 1e-3);

            // Transform only: no chunk is rebuilt.
            live.scene.update_gaussians(0, edited, Matrix4{});
            live.scene.build(mode);
            EXPECT_EQ(live.scene.last_build().gaussian_chunks, 0u);
            TestScene fresh_identity(true);
            fresh_identity.scene.add_mesh(floor.desc());
            fresh_identity.scene.add_gaussians(edited);
            EXPECT_LE(max_difference(render(live.scene, test_camera(), settings(mode, comp)),
                                     render(fresh_identity.scene, test_camera(), settings(mode, comp))),
                      1e-6);

            // Moving without new data (the viewport's object move): instance transforms only, no primitive work.
            live.scene.set_gaussians_transform(0, moved);
            live.scene.build(mode);
            EXPECT_FALSE(live.scene.last_build().full);
            EXPECT_EQ(live.scene.last_build().gaussian_chunks, 0u);
            EXPECT_LE(max_difference(render(live.scene, test_camera(), settings(mode, comp)), expected), 1e-6);
        }
}

// Changing a few Gaussians of the cloud in place (Scene::gaussians_changed, the viewport's edit of a few splats)
// recomputes only their primitives and rebuilds only their chunk; the image equals a fresh scene's. Both modes,
// sorted and stochastic, with the object moved at the same time.
TEST(RenderUpdate, ChangedRowsRenderLikeAFreshScene) {
    for (GaussianMode mode : {GaussianMode::Flat, GaussianMode::Volumetric})
        for (Compositing comp : {Compositing::Sorted, Compositing::Stochastic}) {
            const GaussianCloud original = random_cloud(11, 400, 1.0f);
            GaussianCloud live_cloud = original;  // the scene keeps a pointer to it; edited in place below
            TestScene live(true);
            live.scene.add_gaussians(live_cloud);
            live.scene.build(mode);

            const std::uint32_t rows[] = {17, 18};
            nudge(live_cloud, 17, 0.08f);
            live_cloud.scales[3 * 18] *= 1.7f;
            live_cloud.opacities[18] = 0.9f;
            live.scene.gaussians_changed(0, rows, 2);
            const Matrix4 moved = Matrix4::translation(0.1f, -0.05f, 0.2f);
            live.scene.set_gaussians_transform(0, moved);
            live.scene.build(mode);
            const Scene::BuildReport report = live.scene.last_build();
            EXPECT_FALSE(report.full);
            EXPECT_GE(report.gaussian_chunks, 1u);
            EXPECT_LE(report.gaussian_chunks, 2u);  // of 7
            const Film updated = render(live.scene, test_camera(), settings(mode, comp));

            TestScene fresh(true);
            fresh.scene.add_gaussians(live_cloud, moved);
            EXPECT_LE(max_difference(updated, render(fresh.scene, test_camera(), settings(mode, comp))), 1e-6)
                << "mode " << int(mode) << " comp " << int(comp);
            TestScene before(true);
            before.scene.add_gaussians(original, moved);
            EXPECT_GT(max_difference(updated, render(before.scene, test_camera(), settings(mode, comp))), 1e-3);

            // Rows whose values did not change rebuild nothing.
            live.scene.gaussians_changed(0, rows, 2);
            live.scene.build(mode);
            EXPECT_EQ(live.scene.last_build().gaussian_chunks, 0u);
        }
}

TEST(RenderUpdate, BadChangedRowsAreRefused) {
    GaussianCloud cloud = random_cloud(12, 50, 1.0f);
    TestScene live(true);
    live.scene.add_gaussians(cloud);
    live.scene.build(GaussianMode::Flat);
    const std::uint32_t out_of_range[] = {50};
    EXPECT_THROW(live.scene.gaussians_changed(0, out_of_range, 1), InvalidArgument);
    EXPECT_THROW(live.scene.gaussians_changed(1, out_of_range, 0), InvalidArgument);
    // GaussianCloud::assign_rows (the bindings' way to change rows) validates everything before it writes.
    const GaussianCloud kept = cloud;
    GaussianCloud values = random_cloud(13, 2, 1.0f);
    const std::uint32_t rows[] = {3, 50};
    EXPECT_THROW(cloud.assign_rows(values, rows, "cloud"), InvalidArgument);  // row 50 does not exist
    values.opacities[1] = std::nanf("");
    const std::uint32_t good_rows[] = {3, 4};
    EXPECT_THROW(cloud.assign_rows(values, good_rows, "cloud"), InvalidArgument);
    EXPECT_EQ(cloud.positions, kept.positions);
    EXPECT_EQ(cloud.opacities, kept.opacities);
    values.opacities[1] = 0.5f;
    cloud.assign_rows(values, good_rows, "cloud");
    EXPECT_EQ(cloud.opacities[4], 0.5f);
    EXPECT_EQ(cloud.positions[3 * 3], values.positions[0]);

    cloud.scales[3 * 7 + 1] = std::nanf("");
    const std::uint32_t bad[] = {7};
    try {
        live.scene.gaussians_changed(0, bad, 1);
        ADD_FAILURE() << "a NaN scale was accepted";
    } catch (const InvalidArgument& e) {
        EXPECT_NE(std::string(e.what()).find("Gaussian 7"), std::string::npos) << e.what();
    }
}

// A different count (Gaussians deleted) rebuilds everything and still renders like a fresh scene.
TEST(RenderUpdate, ChangedCountRebuildsEverything) {
    const GaussianCloud original = random_cloud(8, 300, 1.0f);
    GaussianCloud fewer = random_cloud(8, 200, 1.0f);
    TestScene live(true);
    live.scene.add_gaussians(original);
    live.scene.build(GaussianMode::Flat);
    live.scene.update_gaussians(0, fewer, Matrix4{});
    live.scene.build(GaussianMode::Flat);
    EXPECT_TRUE(live.scene.last_build().full);
    TestScene fresh(true);
    fresh.scene.add_gaussians(fewer);
    const RenderSettings s = settings(GaussianMode::Flat, Compositing::Sorted);
    EXPECT_LE(max_difference(render(live.scene, test_camera(), s), render(fresh.scene, test_camera(), s)), 1e-6);
}

// An edited mesh (vertices moved, new transform) rebuilds only its own BVH.
TEST(RenderUpdate, UpdatedMeshRendersLikeAFreshScene) {
    const GaussianCloud cloud = random_cloud(9, 200, 1.0f);
    const TestMesh a = make_quad_z(-1.5f, 1.5f, -1.5f, 1.5f, -0.6f, 0);
    const TestMesh b = make_quad_z(-0.5f, 0.5f, -0.5f, 0.5f, 0.0f, 0);
    TestMesh b_edited = b;
    b_edited.vertices[0] -= 0.4f;  // one corner pulled out
    b_edited.object_to_world = Matrix4::translation(0.2f, 0.1f, 0.3f);
    TestScene live(true);
    live.scene.add_mesh(a.desc());
    live.scene.add_mesh(b.desc());
    live.scene.add_gaussians(cloud);
    live.scene.build(GaussianMode::Flat);
    live.scene.update_mesh(1, b_edited.desc());
    live.scene.build(GaussianMode::Flat);
    EXPECT_FALSE(live.scene.last_build().full);
    EXPECT_EQ(live.scene.last_build().meshes, 1u);
    EXPECT_EQ(live.scene.last_build().gaussian_chunks, 0u);
    TestScene fresh(true);
    fresh.scene.add_mesh(a.desc());
    fresh.scene.add_mesh(b_edited.desc());
    fresh.scene.add_gaussians(cloud);
    const RenderSettings s = settings(GaussianMode::Flat, Compositing::Sorted);
    EXPECT_LE(max_difference(render(live.scene, test_camera(), s), render(fresh.scene, test_camera(), s)), 1e-6);
}

// Bad updates are refused with a clear error and leave the scene as it was.
TEST(RenderUpdate, BadUpdatesAreRefused) {
    const GaussianCloud cloud = random_cloud(10, 50, 1.0f);
    TestScene live(true);
    live.scene.add_gaussians(cloud);
    EXPECT_THROW(live.scene.update_gaussians(1, cloud, Matrix4{}), InvalidArgument);
    EXPECT_THROW(live.scene.set_gaussians_transform(1, Matrix4{}), InvalidArgument);
    EXPECT_THROW(live.scene.set_gaussians_transform(0, Matrix4::scale(0, 1, 1)), InvalidArgument);
    GaussianCloud bad = cloud;
    bad.positions[4] = std::nanf("");
    EXPECT_THROW(live.scene.update_gaussians(0, bad, Matrix4{}), InvalidArgument);
    const TestMesh m = make_quad_z(-1, 1, -1, 1, 0, 0);
    EXPECT_THROW(live.scene.update_mesh(0, m.desc()), InvalidArgument);
    EXPECT_THROW(live.scene.set_interactive(true, 0), InvalidArgument);
    const RenderSettings s = settings(GaussianMode::Flat, Compositing::Sorted);
    TestScene fresh(true);
    fresh.scene.add_gaussians(cloud);
    EXPECT_LE(max_difference(render(live.scene, test_camera(), s), render(fresh.scene, test_camera(), s)), 1e-6);
}

}  // namespace raysplats

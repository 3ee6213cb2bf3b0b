#include "render/renderer.h"

#define GL_GLEXT_PROTOTYPES 1
#include <GL/osmesa.h>
// osmesa.h brings GL/gl.h; the 3.3 entry points are declared by glext.h and exported by
// libOSMesa itself.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <GL/glext.h>
#include <fmt/format.h>

#include "fusion/body/skeleton.h"

namespace caphub::render {

std::optional<CameraPreset> parseCameraPreset(std::string_view name) {
    if (name == "front") {
        return CameraPreset::Front;
    }
    if (name == "side") {
        return CameraPreset::Side;
    }
    if (name == "orbit") {
        return CameraPreset::Orbit;
    }
    if (name == "follow") {
        return CameraPreset::Follow;
    }
    return std::nullopt;
}

namespace {

using Mat4f = Eigen::Matrix4f;
using Vec3f = Eigen::Vector3f;

std::int64_t nowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

constexpr const char* kMeshVs = R"(#version 330 core
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aNormal;
uniform mat4 uViewProj;
out vec3 vNormal;
void main() {
    vNormal = aNormal;
    gl_Position = uViewProj * vec4(aPos, 1.0);
}
)";

// Two directional lights (key from the front-left above, fill from behind) and an ambient term;
// two-sided so that open edges of the mesh do not show black.
constexpr const char* kMeshFs = R"(#version 330 core
in vec3 vNormal;
uniform vec3 uColor;
out vec4 fragColor;
void main() {
    vec3 n = normalize(vNormal);
    if (!gl_FrontFacing) n = -n;
    float key = max(dot(n, normalize(vec3(0.4, 0.8, 0.6))), 0.0);
    float fill = max(dot(n, normalize(vec3(-0.5, 0.3, -0.7))), 0.0);
    vec3 c = uColor * (0.28 + 0.62 * key + 0.25 * fill);
    fragColor = vec4(min(c, vec3(1.0)), 1.0);
}
)";

constexpr const char* kLineVs = R"(#version 330 core
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aColor;
uniform mat4 uViewProj;
uniform float uPointSize;
out vec3 vColor;
void main() {
    vColor = aColor;
    gl_PointSize = uPointSize;
    gl_Position = uViewProj * vec4(aPos, 1.0);
}
)";

constexpr const char* kLineFs = R"(#version 330 core
in vec3 vColor;
out vec4 fragColor;
void main() { fragColor = vec4(vColor, 1.0); }
)";

Result<GLuint> compile(GLenum type, const char* src) {
    const GLuint s = glCreateShader(type);
    glShaderSource(s, 1, &src, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[1024] = {};
        glGetShaderInfoLog(s, sizeof log, nullptr, log);
        glDeleteShader(s);
        return Error{EINVAL, fmt::format("shader compile: {}", log)};
    }
    return s;
}

Result<GLuint> program(const char* vs, const char* fs) {
    auto v = compile(GL_VERTEX_SHADER, vs);
    if (!v) {
        return v.error();
    }
    auto f = compile(GL_FRAGMENT_SHADER, fs);
    if (!f) {
        glDeleteShader(*v);
        return f.error();
    }
    const GLuint p = glCreateProgram();
    glAttachShader(p, *v);
    glAttachShader(p, *f);
    glLinkProgram(p);
    glDeleteShader(*v);
    glDeleteShader(*f);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
        char log[1024] = {};
        glGetProgramInfoLog(p, sizeof log, nullptr, log);
        glDeleteProgram(p);
        return Error{EINVAL, fmt::format("shader link: {}", log)};
    }
    return p;
}

Mat4f lookAt(const Vec3f& eye, const Vec3f& target, const Vec3f& up) {
    const Vec3f f = (target - eye).normalized();
    const Vec3f s = f.cross(up).normalized();
    const Vec3f u = s.cross(f);
    Mat4f m = Mat4f::Identity();
    m.block<1, 3>(0, 0) = s.transpose();
    m.block<1, 3>(1, 0) = u.transpose();
    m.block<1, 3>(2, 0) = -f.transpose();
    m(0, 3) = -s.dot(eye);
    m(1, 3) = -u.dot(eye);
    m(2, 3) = f.dot(eye);
    return m;
}

Mat4f perspective(float fovYRad, float aspect, float nearM, float farM) {
    const float t = 1.0f / std::tan(fovYRad / 2);
    Mat4f m = Mat4f::Zero();
    m(0, 0) = t / aspect;
    m(1, 1) = t;
    m(2, 2) = (farM + nearM) / (nearM - farM);
    m(2, 3) = 2 * farM * nearM / (nearM - farM);
    m(3, 2) = -1;
    return m;
}

}  // namespace

// One vertex of the grid, bones and markers (a member type of the GL state, so not file-local).
struct RendererLineVertex {
    float p[3];
    float c[3];
};

struct Renderer::Gl {
    OSMesaContext ctx = nullptr;
    std::vector<std::uint8_t> rgba;
    GLuint meshProgram = 0, lineProgram = 0;
    GLuint meshVao = 0, meshVbo = 0, meshEbo = 0;
    GLuint lineVao = 0, lineVbo = 0;
    GLsizei indexCount = 0;
    GLint meshViewProj = -1, meshColor = -1, lineViewProj = -1, linePointSize = -1;
    std::vector<RendererLineVertex> lines;
    std::size_t gridVertices = 0;

    ~Gl() {
        if (ctx) {
            OSMesaDestroyContext(ctx);
        }
    }
};

Result<std::unique_ptr<Renderer>> Renderer::create(const Skin& skin, const RenderOptions& options) {
    if (options.width < 16 || options.height < 16 || options.width > 4096 ||
        options.height > 4096) {
        return Error{EINVAL, fmt::format("preview size {}x{}: expected 16 to 4096 each",
                                         options.width, options.height)};
    }
    std::unique_ptr<Renderer> r(new Renderer);
    r->options_ = options;
    {
        const auto& o = skin.jointOriginsM;
        const Vec3d pelvis(o[0][0], o[0][1], o[0][2]);
        double reach = 0;
        for (const auto& j : o) {
            reach = std::max(reach, (Vec3d(j[0], j[1], j[2]) - pelvis).norm());
        }
        // The joints end at the wrists, the skull's base and the toes: the hands, the top of
        // the head and the skin's thickness lie up to ~0.3 m beyond them.
        r->framingRadiusM_ = std::clamp(reach + 0.3, 0.5, 3.0);
    }
    r->gl_ = std::make_unique<Gl>();
    auto& gl = *r->gl_;
    const int attribs[] = {OSMESA_FORMAT,
                           OSMESA_RGBA,
                           OSMESA_DEPTH_BITS,
                           24,
                           OSMESA_PROFILE,
                           OSMESA_CORE_PROFILE,
                           OSMESA_CONTEXT_MAJOR_VERSION,
                           3,
                           OSMESA_CONTEXT_MINOR_VERSION,
                           3,
                           0};
    gl.ctx = OSMesaCreateContextAttribs(attribs, nullptr);
    if (!gl.ctx) {
        return Error{ENODEV, "OSMesa: no GL 3.3 core context (is Mesa's llvmpipe available?)"};
    }
    gl.rgba.resize(static_cast<std::size_t>(options.width) * options.height * 4);
    if (!OSMesaMakeCurrent(gl.ctx, gl.rgba.data(), GL_UNSIGNED_BYTE, options.width,
                           options.height)) {
        return Error{ENODEV, "OSMesa: could not make the context current"};
    }
    auto mp = program(kMeshVs, kMeshFs);
    if (!mp) {
        return mp.error();
    }
    auto lp = program(kLineVs, kLineFs);
    if (!lp) {
        return lp.error();
    }
    gl.meshProgram = *mp;
    gl.lineProgram = *lp;
    gl.meshViewProj = glGetUniformLocation(gl.meshProgram, "uViewProj");
    gl.meshColor = glGetUniformLocation(gl.meshProgram, "uColor");
    gl.lineViewProj = glGetUniformLocation(gl.lineProgram, "uViewProj");
    gl.linePointSize = glGetUniformLocation(gl.lineProgram, "uPointSize");

    glGenVertexArrays(1, &gl.meshVao);
    glBindVertexArray(gl.meshVao);
    glGenBuffers(1, &gl.meshVbo);
    glBindBuffer(GL_ARRAY_BUFFER, gl.meshVbo);
    r->vertexCount_ = skin.vertexCount();
    glBufferData(GL_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(skin.vertexCount() * sizeof(SkinnedVertex)), nullptr,
                 GL_STREAM_DRAW);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(SkinnedVertex),
                          reinterpret_cast<void*>(offsetof(SkinnedVertex, position)));
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(SkinnedVertex),
                          reinterpret_cast<void*>(offsetof(SkinnedVertex, normal)));
    glEnableVertexAttribArray(0);
    glEnableVertexAttribArray(1);
    glGenBuffers(1, &gl.meshEbo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, gl.meshEbo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(skin.triangles.size() * sizeof(skin.triangles[0])),
                 skin.triangles.data(), GL_STATIC_DRAW);
    gl.indexCount = static_cast<GLsizei>(skin.triangles.size() * 3);

    glGenVertexArrays(1, &gl.lineVao);
    glBindVertexArray(gl.lineVao);
    glGenBuffers(1, &gl.lineVbo);
    glBindBuffer(GL_ARRAY_BUFFER, gl.lineVbo);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(RendererLineVertex),
                          reinterpret_cast<void*>(offsetof(RendererLineVertex, p)));
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(RendererLineVertex),
                          reinterpret_cast<void*>(offsetof(RendererLineVertex, c)));
    glEnableVertexAttribArray(0);
    glEnableVertexAttribArray(1);
    glBindVertexArray(0);

    // The floor grid: 6 m x 6 m in 0.5 m squares, the axes through the origin darker.
    for (int i = -6; i <= 6; ++i) {
        const float d = static_cast<float>(i) * 0.5f;
        const float g = i == 0 ? 0.25f : 0.45f;
        gl.lines.push_back({{d, 0, -3}, {g, g, g}});
        gl.lines.push_back({{d, 0, 3}, {g, g, g}});
        gl.lines.push_back({{-3, 0, d}, {g, g, g}});
        gl.lines.push_back({{3, 0, d}, {g, g, g}});
    }
    gl.gridVertices = gl.lines.size();
    if (glGetError() != GL_NO_ERROR) {
        return Error{EIO, "OpenGL error while setting up the preview"};
    }
    return r;
}

Renderer::~Renderer() = default;

Result<void> Renderer::render(const FrameInput& frame, Image& out, StageTimes* times) {
    auto& gl = *gl_;
    if (frame.vertices.size() != vertexCount_) {
        return Error{EINVAL, fmt::format("preview: {} vertices for a skin of {}",
                                         frame.vertices.size(), vertexCount_)};
    }
    const int w = options_.width, h = options_.height;
    if (!OSMesaMakeCurrent(gl.ctx, gl.rgba.data(), GL_UNSIGNED_BYTE, w, h)) {
        return Error{ENODEV, "OSMesa: could not make the context current"};
    }
    const std::int64_t t0 = nowNs();
    glBindBuffer(GL_ARRAY_BUFFER, gl.meshVbo);
    glBufferSubData(GL_ARRAY_BUFFER, 0,
                    static_cast<GLsizeiptr>(frame.vertices.size() * sizeof(SkinnedVertex)),
                    frame.vertices.data());

    // Overlay geometry: the skeleton's bones and the sensor markers.
    gl.lines.resize(gl.gridVertices);
    const auto& J = frame.jointsM;
    auto f3 = [](const Vec3d& v, float r, float g, float b) {
        return RendererLineVertex{
            {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())},
            {r, g, b}};
    };
    std::array<int, kSegmentCount> firstChild;
    firstChild.fill(-1);
    for (const auto& info : body::joints()) {
        if (info.parent >= 0 && firstChild[static_cast<std::size_t>(info.parent)] < 0) {
            firstChild[static_cast<std::size_t>(info.parent)] = body::idx(info.segment);
        }
    }
    const std::size_t boneStart = gl.lines.size();
    if (options_.drawSkeleton) {
        for (const auto& info : body::joints()) {
            if (info.parent < 0) {
                continue;
            }
            gl.lines.push_back(f3(J[static_cast<std::size_t>(info.parent)], 0.1f, 0.35f, 0.95f));
            gl.lines.push_back(
                f3(J[static_cast<std::size_t>(body::idx(info.segment))], 0.1f, 0.35f, 0.95f));
        }
    }
    const std::size_t markerStart = gl.lines.size();
    if (options_.drawSensors) {
        for (int s = 0; s < kSegmentCount; ++s) {
            const auto st = frame.sensors[static_cast<std::size_t>(s)];
            if (st == SensorState::None) {
                continue;
            }
            // Half-way along the segment; end segments: a little beyond their joint.
            const auto si = static_cast<std::size_t>(s);
            const int c = firstChild[si];
            const int p = body::parentOf(s);
            Vec3d at = J[si];
            if (c >= 0) {
                at = 0.5 * (J[si] + J[static_cast<std::size_t>(c)]);
            } else if (p >= 0) {
                at = J[si] + 0.3 * (J[si] - J[static_cast<std::size_t>(p)]);
            }
            const float r = st == SensorState::Ok ? 0.1f : 1.0f;
            const float g =
                st == SensorState::Lost ? 0.1f : (st == SensorState::Ok ? 0.85f : 0.85f);
            const float b = 0.1f;
            gl.lines.push_back(f3(at, r, g, b));
        }
    }
    glBindBuffer(GL_ARRAY_BUFFER, gl.lineVbo);
    glBufferData(GL_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(gl.lines.size() * sizeof(RendererLineVertex)),
                 gl.lines.data(), GL_STREAM_DRAW);
    const std::int64_t t1 = nowNs();

    // Camera: looking at the pelvis, wherever the subject is, from the preset's direction, at
    // the distance that fits the framing sphere into the narrower of the two fields of view.
    const Vec3d pelvis = J[0];
    const Vec3f target(static_cast<float>(pelvis.x()), static_cast<float>(pelvis.y()),
                       static_cast<float>(pelvis.z()));
    Vec3f direction(0, 0.05f, 1);
    switch (options_.camera) {
        case CameraPreset::Front:
            direction = Vec3f(0, 0.05f, 1);
            break;
        case CameraPreset::Side:
            direction = Vec3f(1, 0.05f, 0);
            break;
        case CameraPreset::Orbit: {
            const float a = static_cast<float>(frame.timeS * 2 * M_PI / 20.0);
            direction = Vec3f(std::sin(a), 0.2f, std::cos(a));
            break;
        }
        case CameraPreset::Follow:
            direction = Vec3f(2.2f, 0.5f, 3.5f);
            break;
    }
    const double vFov = 32.0 * M_PI / 180.0;
    const double aspect = static_cast<double>(w) / static_cast<double>(h);
    const double hFov = 2 * std::atan(std::tan(vFov / 2) * aspect);
    const double distance = framingRadiusM_ / std::sin(std::min(vFov, hFov) / 2);
    const Vec3f eye = target + direction.normalized() * static_cast<float>(distance);
    const Mat4f viewProj = perspective(static_cast<float>(vFov), static_cast<float>(aspect), 0.1f,
                                       static_cast<float>(distance + 20.0)) *
                           lookAt(eye, target, Vec3f::UnitY());

    glViewport(0, 0, w, h);
    glClearColor(0.86f, 0.88f, 0.92f, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glEnable(GL_DEPTH_TEST);
    glEnable(GL_PROGRAM_POINT_SIZE);

    glUseProgram(gl.lineProgram);
    glUniformMatrix4fv(gl.lineViewProj, 1, GL_FALSE, viewProj.data());
    glUniform1f(gl.linePointSize, 1.0f);
    glBindVertexArray(gl.lineVao);
    if (options_.drawGrid) {
        glDrawArrays(GL_LINES, 0, static_cast<GLsizei>(gl.gridVertices));
    }

    glUseProgram(gl.meshProgram);
    glUniformMatrix4fv(gl.meshViewProj, 1, GL_FALSE, viewProj.data());
    glUniform3f(gl.meshColor, 0.87f, 0.71f, 0.60f);
    glBindVertexArray(gl.meshVao);
    glDrawElements(GL_TRIANGLES, gl.indexCount, GL_UNSIGNED_INT, nullptr);

    // The skeleton and the sensors on top of the skin.
    glDisable(GL_DEPTH_TEST);
    glUseProgram(gl.lineProgram);
    glBindVertexArray(gl.lineVao);
    glDrawArrays(GL_LINES, static_cast<GLint>(boneStart),
                 static_cast<GLsizei>(markerStart - boneStart));
    const float pointPx = static_cast<float>(std::max(5, h / 40));
    glUniform1f(gl.linePointSize, pointPx);
    glDrawArrays(GL_POINTS, static_cast<GLint>(markerStart),
                 static_cast<GLsizei>(gl.lines.size() - markerStart));
    glBindVertexArray(0);
    glFinish();
    const GLenum err = glGetError();
    const std::int64_t t2 = nowNs();
    if (err != GL_NO_ERROR) {
        return Error{EIO, fmt::format("OpenGL error 0x{:x} while drawing the preview", err)};
    }

    // OSMesa's rows run bottom to top.
    if (out.width != w || out.height != h) {
        out = Image(w, h);
    }
    for (int y = 0; y < h; ++y) {
        const std::uint8_t* src = gl.rgba.data() + static_cast<std::size_t>(h - 1 - y) * w * 4;
        std::uint8_t* dst = out.pixel(0, y);
        for (int x = 0; x < w; ++x) {
            dst[3 * x] = src[4 * x];
            dst[3 * x + 1] = src[4 * x + 1];
            dst[3 * x + 2] = src[4 * x + 2];
        }
    }
    const std::int64_t t3 = nowNs();
    if (times) {
        times->uploadNs = t1 - t0;
        times->drawNs = t2 - t1;
        times->readbackNs = t3 - t2;
    }
    return {};
}

}  // namespace caphub::render

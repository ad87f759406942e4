#pragma once
// A GLES 3.2 context on Mesa's llvmpipe (or any EGL device) through EGL surfaceless, for the
// tests that run shipped shaders. Compiled only where CMake found EGL and GLES (SPECBAKE_HAVE_GL).
#ifdef SPECBAKE_HAVE_GL
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>

#include <string>

namespace specbake::testing {

struct GlContext {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  std::string why;  // empty when current; else why there is no context (the test skips)
  GlContext() {
    auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!get_display) { why = "no eglGetPlatformDisplayEXT"; return; }
    dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, nullptr, nullptr)) { why = "no surfaceless EGL display"; return; }
    if (!eglBindAPI(EGL_OPENGL_ES_API)) { why = "EGL cannot bind OpenGL ES"; return; }
    const EGLint attrs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 2, EGL_NONE};
    ctx = eglCreateContext(dpy, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attrs);
    if (ctx == EGL_NO_CONTEXT) { why = "no GLES 3.2 context without a config"; return; }
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) why = "cannot make the context current";
  }
  ~GlContext() {
    if (ctx != EGL_NO_CONTEXT) eglDestroyContext(dpy, ctx);
    if (dpy != EGL_NO_DISPLAY) eglTerminate(dpy);
  }
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;
};

inline bool gl_has_extension(const char* name) {
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  for (GLint i = 0; i < n; ++i)
    if (std::string(reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, i))) == name) return true;
  return false;
}

// A program from a vertex and a fragment shader; 0 with the compile/link log in `log` on failure.
inline GLuint gl_program(const std::string& vs, const std::string& fs, std::string& log) {
  const auto compile = [&](GLenum type, const std::string& src) {
    const GLuint s = glCreateShader(type);
    const char* p = src.c_str();
    glShaderSource(s, 1, &p, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char buf[4096];
      glGetShaderInfoLog(s, sizeof buf, nullptr, buf);
      log += buf;
    }
    return s;
  };
  const GLuint prog = glCreateProgram();
  glAttachShader(prog, compile(GL_VERTEX_SHADER, vs));
  glAttachShader(prog, compile(GL_FRAGMENT_SHADER, fs));
  glLinkProgram(prog);
  GLint linked = 0;
  glGetProgramiv(prog, GL_LINK_STATUS, &linked);
  if (!linked) {
    char buf[4096];
    glGetProgramInfoLog(prog, sizeof buf, nullptr, buf);
    log += buf;
    return 0;
  }
  return prog;
}

// A full-screen triangle (no vertex buffers: gl_VertexID).
inline const char* kGlFullScreenVertex =
    "#version 320 es\nvoid main() {\n  vec2 c = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);\n"
    "  gl_Position = vec4(c, 0.0, 1.0);\n}\n";

}  // namespace specbake::testing
#endif

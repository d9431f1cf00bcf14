// render/gl.hpp — the OpenGL declarations render/ uses. libOSMesa exports every
// core entry point itself, so prototypes are enough (no loader).
// Include only from .cpp files built with OSMesa.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/gl.h>
#include <GL/glext.h>
#include <GL/osmesa.h>

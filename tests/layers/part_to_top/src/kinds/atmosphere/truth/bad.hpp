#pragma once
#include "kinds/atmosphere/shader/render.hpp"

#include "kinds/atmosphere/atmosphere_job.hpp"

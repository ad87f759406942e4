#pragma once
#include "kinds/atmosphere/model/spec.hpp"
#include "kinds/atmosphere/bake/pass.hpp"

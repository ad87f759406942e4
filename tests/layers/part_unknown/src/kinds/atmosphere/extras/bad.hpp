#pragma once
#include "kinds/atmosphere/model/spec.hpp"

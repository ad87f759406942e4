#include "kinds/atmosphere/spec.hpp"

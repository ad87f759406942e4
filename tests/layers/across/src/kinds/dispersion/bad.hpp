#include "kinds/atmosphere/model/spec.hpp"

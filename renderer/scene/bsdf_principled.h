// Mitsuba 3's Disney-style BSDFs, `principled` and `principledthin`
// (bsdf_principled.cpp has the model, its parameters and its citations).
#pragma once
#include <memory>

#include "scene/bsdf.h"
#include "scene/desc.h"

namespace rm {

// desc.type "principled" or "principledthin"; throws std::invalid_argument
// naming the BSDF and the parameter on bad values (as make_bsdf).
std::unique_ptr<Bsdf> make_principled(const BsdfDesc& desc);

}  // namespace rm

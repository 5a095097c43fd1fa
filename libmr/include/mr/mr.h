// libmr: the whole public API.
#pragma once

#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/color.h"
#include "mr/depth.h"
#include "mr/depth_fit.h"
#include "mr/depth_network.h"
#include "mr/error.h"
#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/image.h"
#include "mr/io.h"
#include "mr/metadata.h"
#include "mr/scattering.h"
#include "mr/scene.h"
#include "mr/scene_json.h"
#include "mr/version.h"

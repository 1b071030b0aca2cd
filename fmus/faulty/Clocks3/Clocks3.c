/* Clocks3, FMI 3.0: the Source model (../../common/source.h) behind the FMI 3.0 wrapper; its model
 * description is what Coupler must refuse (see fmus/faulty/README.md). */
#include "../../common/source.h"
#include "../../common/fmi3_cosim.c"

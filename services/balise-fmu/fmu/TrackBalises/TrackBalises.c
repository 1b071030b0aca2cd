/* TrackBalises, FMI 2.0 co-simulation: the model in ../model/trackbalises.h behind the FMI 2.0
 * wrapper shared with the example FMUs (fmus/common). */
#include "../model/trackbalises.h"
#include "../../../../fmus/common/fmi2_cosim.c"

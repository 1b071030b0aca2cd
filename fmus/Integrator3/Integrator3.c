/* Integrator, FMI 3.0 co-simulation: the model in ../common/integrator.h behind the FMI 3.0 wrapper. */
#include "../common/integrator.h"
#include "../common/fmi3_cosim.c"

/* Integrator, FMI 2.0 co-simulation: the model in ../common/integrator.h behind the FMI 2.0 wrapper. */
#include "../common/integrator.h"
#include "../common/fmi2_cosim.c"

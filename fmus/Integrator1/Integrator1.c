/* Integrator, FMI 1.0 co-simulation: the model in ../common/integrator.h behind the FMI 1.0 wrapper. */
#include "../common/integrator.h"
#include "../common/fmi1_cosim.c"

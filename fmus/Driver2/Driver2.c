/* Driver, FMI 2.0 co-simulation: the model in ../common/driver.h behind the FMI 2.0 wrapper. */
#include "../common/driver.h"
#include "../common/fmi2_cosim.c"

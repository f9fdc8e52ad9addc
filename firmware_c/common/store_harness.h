/* The state of a C test of the model store (tests/test_store.c, tests/test_store_trial.c): the store under test on
 * the strict RAM NVM (ram_nvm.h) of N_SECT sectors of SECTOR bytes, and the bundle's model image it starts from
 * (image_edit_load). Static, as the rest of each test's state. */
#ifndef STORE_HARNESS_H
#define STORE_HARNESS_H
#include <stddef.h>
#include <stdint.h>

#include "ram_nvm.h"
#include "slipest_image.h"
#include "slipest_store.h"

#define SECTOR 128u
#define N_SECT (SLIPEST_STORE_NVM_SECTORS(SECTOR))

static uint8_t mem[N_SECT * SECTOR];
static ram_nvm_t ram;
static slipest_nvm_t nvm;
static slipest_store_t st;
static uint8_t base_img[SLIPEST_IMAGE_MAX_SIZE];
static size_t base_len;
#endif

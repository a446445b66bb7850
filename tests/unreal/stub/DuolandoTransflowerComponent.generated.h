// TEST STUB — stands in for the file Unreal Header Tool generates.
#pragma once

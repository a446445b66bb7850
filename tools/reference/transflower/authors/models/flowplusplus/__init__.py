from models.flowplusplus.flowplusplus import FlowPlusPlus

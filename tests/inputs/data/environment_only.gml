<?xml version="1.0"?>
<GML>
  <tag>
    <header><client><name>tagbot test (no drawing)</name></client></header>
    <environment>
      <up><x>0</x><y>-1</y><z>0</z></up>
      <screenBounds><x>1024</x><y>768</y><z>0</z></screenBounds>
    </environment>
  </tag>
</GML>

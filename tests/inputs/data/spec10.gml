<?xml version="1.0" encoding="UTF-8"?>
<!-- GML 1.0 layout; written for tagbot's tests -->
<gml spec="1.0">
  <tag>
    <header>
      <client>
        <name>tagbot test</name>
      </client>
      <environment>
        <up><x>0</x><y>-1</y><z>0</z></up>
        <screenBounds><x>1000</x><y>1000</y><z>0</z></screenBounds>
      </environment>
    </header>
    <drawing>
      <stroke>
        <pt><x>0.1</x><y>0.2</y><z>0.5</z><t>0.5</t><pres>0.9</pres></pt>
        <pt><x>0.3</x><y>0.2</y><z>0.6</z><t>0.6</t></pt>
        <pt><x>0.3</x><y>0.6</y><t>0.7</t></pt>
      </stroke>
      <stroke isDrawing="false">
        <pt><x>0.3</x><y>0.6</y><t>0.8</t></pt>
        <pt><x>0.5</x><y>0.6</y><t>0.9</t></pt>
      </stroke>
      <stroke>
        <pt><x>0.5</x><y>0.6</y><t>1.0</t></pt>
        <pt><x>0.6</x><y>0.4</y><t>1.1</t></pt>
      </stroke>
    </drawing>
    <drawing>
      <stroke>
        <pt><x>0.7</x><y>0.2</y><t>1.5</t></pt>
        <pt><x>0.8</x><y>0.25</y><t>1.6</t></pt>
      </stroke>
    </drawing>
  </tag>
  <tag>
    <drawing>
      <stroke>
        <pt><x>0.2</x><y>0.8</y><t>2.0</t></pt>
        <pt><x>0.9</x><y>0.9</y><t>2.5</t></pt>
      </stroke>
    </drawing>
  </tag>
</gml>
